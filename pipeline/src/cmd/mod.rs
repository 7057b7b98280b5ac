pub mod schema;
pub mod simulate;
