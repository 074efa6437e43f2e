pub mod models;
pub mod reference;
