//! robotid's pipeline stages and the numerical cores they share.
//!
//! - [`stage`]: the pipeline stages, one module each (`read`, `align`,
//!   `inverse_filter`, `decimate`, `average`, `noise`, `differentiate`,
//!   `regressor`, `estimate`): a serde config, what it takes and makes, a
//!   `build` done once per run and a `run` on one recording's [`stage::Chain`].
//! - The cores, which know nothing of stages: [`dynamics`] (rigid-body
//!   models, RNEA, regressors, base parameters), [`signal`] (spectra, analog
//!   filters), [`estimation`] (least squares, maximum likelihood, physical
//!   consistency, the Projection Method, dedicated experiments),
//!   [`excitation`] (optimal excitation design), [`simulation`] (the
//!   closed-loop simulator), [`trajectory`] and [`formats`] (files), and
//!   [`export`] (a model written as URDF or MJCF, or patched into the
//!   user's own).

pub mod dynamics;
mod error;
pub mod estimation;
pub mod excitation;
pub mod export;
pub mod formats;
pub mod signal;
pub mod simulation;
pub mod stage;
pub mod trajectory;

pub use error::{relocate_path, toml_message as error_message_of_toml, Error, Problem, Result};
