//! robotid's stages and the numerical cores they share.

pub mod dynamics;
mod error;
pub mod formats;
pub mod signal;
pub mod simulate;
pub mod trajectory;

pub use error::{Error, Result};
