#!/usr/bin/env bash
# Comments say why, not when: no "issue N", commit hashes or dates in the
# comments of Rust sources (history belongs in git). Prints each offending
# line and fails if there is one.
set -euo pipefail
cd "$(dirname "$0")/.."

files=$(git ls-files '*.rs')
# A comment: text after `//` (line, doc and inner doc comments).
comments() { grep -nHE '//' $files | sed -E 's#^([^:]+:[0-9]+:).*//#\1 //#'; }
pattern='\b[Ii]ssues? #?[0-9]+|\b(commit|at|since|before|on) (?=[0-9a-f]*[a-f])[0-9a-f]{7,40}\b|\b20[0-9]{2}-[01][0-9]-[0-3][0-9]\b'
# (grep exits 1 when nothing matches, 2 on an error: only 1 is clean.)
status=0
bad=$(comments | grep -P "$pattern") || status=$?
if [ "$status" -gt 1 ]; then
  echo "comment_hygiene: grep failed" >&2
  exit 2
fi
if [ -n "$bad" ]; then
  echo "Comments that say when, not why (issue numbers, commits, dates):"
  echo "$bad"
  exit 1
fi
echo "comment hygiene: ok ($(echo "$files" | wc -l) files)"
