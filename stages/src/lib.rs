//! robotid's stages and the numerical cores they share.

pub mod align;
pub mod average;
pub mod decimate;
pub mod dedicated;
pub mod differentiate;
pub mod dynamics;
mod error;
pub mod estimate;
pub mod excite;
pub mod formats;
pub mod inverse_filter;
pub mod noise;
pub mod projection;
pub mod read;
pub mod regressor;
pub mod signal;
pub mod simulate;
pub mod synthetic;
pub mod trajectory;

pub use error::{toml_message as error_message_of_toml, Error, Result};
