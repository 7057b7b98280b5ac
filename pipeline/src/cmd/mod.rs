pub mod check;
pub mod run;
pub mod schema;
pub mod simulate;
pub mod validate;
