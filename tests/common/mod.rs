pub mod alloc;
pub mod models;
pub mod reference;
