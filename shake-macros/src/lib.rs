//! The `constrained_system!` macro (placeholder until the pipeline lands).
use proc_macro::TokenStream;

/// Declares a constrained Hamiltonian system. Grammar: see the crate docs (to come).
#[proc_macro]
pub fn constrained_system(input: TokenStream) -> TokenStream {
    let _ = input;
    TokenStream::new()
}
