//! robotid's stages and the numerical cores they share.

pub mod dynamics;
mod error;

pub use error::{Error, Result};
