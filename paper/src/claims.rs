//! The table of claims: each claim of the paper (numbered as in the README's
//! table "What the paper claims") next to what this run measured and the bound the theory gives.

use std::fmt::Write as _;
use std::fs;
use std::path::Path;

/// The bound a measurement must satisfy, with the reason it is that bound.
#[derive(Clone, Debug)]
pub enum Bound {
    /// measured ≤ value.
    AtMost(f64),
    /// measured ≥ value.
    AtLeast(f64),
    /// lo ≤ measured ≤ hi.
    Within(f64, f64),
}

impl Bound {
    fn holds(&self, v: f64) -> bool {
        match *self {
            Bound::AtMost(b) => v <= b,
            Bound::AtLeast(b) => v >= b,
            Bound::Within(lo, hi) => lo <= v && v <= hi,
        }
    }

    fn show(&self) -> String {
        match *self {
            Bound::AtMost(b) => format!("<= {}", num(b)),
            Bound::AtLeast(b) => format!(">= {}", num(b)),
            Bound::Within(lo, hi) => format!("in [{}, {}]", num(lo), num(hi)),
        }
    }
}

fn num(v: f64) -> String {
    if v == 0.0 {
        "0".into()
    } else if v.abs() < 1e-3 || v.abs() >= 1e4 {
        format!("{v:.2e}")
    } else {
        format!("{v:.4}")
    }
}

/// One row of the table.
#[derive(Clone, Debug)]
pub struct Claim {
    /// The claim's number in the README's table, e.g. "8".
    pub id: String,
    /// What is claimed, in a sentence.
    pub statement: String,
    /// What was measured (the quantity's name).
    pub quantity: String,
    pub measured: f64,
    pub bound: Bound,
    /// Where the bound comes from (round-off, O(h), order p, ...).
    pub why: String,
}

impl Claim {
    pub fn passes(&self) -> bool {
        self.measured.is_finite() && self.bound.holds(self.measured)
    }
}

/// All claims of a run.
#[derive(Default, Debug)]
pub struct Claims {
    rows: Vec<Claim>,
}

impl Claims {
    /// Records a claim and prints its line at once, so a long run shows
    /// progress.
    pub fn check(
        &mut self,
        id: &str,
        statement: &str,
        quantity: &str,
        measured: f64,
        bound: Bound,
        why: &str,
    ) -> bool {
        let c = Claim {
            id: id.into(),
            statement: statement.into(),
            quantity: quantity.into(),
            measured,
            bound,
            why: why.into(),
        };
        let ok = c.passes();
        println!(
            "  [{}] {:>3}  {}: {} = {} ({})",
            if ok { "pass" } else { "FAIL" },
            c.id,
            c.statement,
            c.quantity,
            num(c.measured),
            c.bound.show()
        );
        self.rows.push(c);
        ok
    }

    pub fn all_pass(&self) -> bool {
        self.rows.iter().all(Claim::passes)
    }

    pub fn failures(&self) -> usize {
        self.rows.iter().filter(|c| !c.passes()).count()
    }

    pub fn len(&self) -> usize {
        self.rows.len()
    }

    /// The table as Markdown.
    pub fn markdown(&self) -> String {
        let mut s = String::from(
            "| # | claim | measured quantity | measured | bound | why this bound | result |\n\
             |---|---|---|---|---|---|---|\n",
        );
        // Norms |g| inside a cell would end it: escape the bars.
        let cell = |t: &str| t.replace('|', "\\|");
        for c in &self.rows {
            let _ = writeln!(
                s,
                "| {} | {} | {} | {} | {} | {} | {} |",
                c.id,
                cell(&c.statement),
                cell(&c.quantity),
                num(c.measured),
                cell(&c.bound.show()),
                cell(&c.why),
                if c.passes() { "pass" } else { "**FAIL**" }
            );
        }
        s
    }

    /// Writes `claims.md` (the preamble, then the table) and `claims.csv`
    /// into `dir`.
    pub fn save(&self, dir: &Path, preamble: &str) -> std::io::Result<()> {
        fs::create_dir_all(dir)?;
        fs::write(
            dir.join("claims.md"),
            format!("{preamble}{}", self.markdown()),
        )?;
        let mut csv = String::from("id,statement,quantity,measured,bound,why,pass\n");
        for c in &self.rows {
            let q = |s: &str| format!("\"{}\"", s.replace('"', "\"\""));
            let _ = writeln!(
                csv,
                "{},{},{},{:e},{},{},{}",
                q(&c.id),
                q(&c.statement),
                q(&c.quantity),
                c.measured,
                q(&c.bound.show()),
                q(&c.why),
                c.passes()
            );
        }
        fs::write(dir.join("claims.csv"), csv)
    }
}
