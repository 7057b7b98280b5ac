pub mod check;
pub mod model;
pub mod run;
pub mod schema;
pub mod simulate;
pub mod validate;
