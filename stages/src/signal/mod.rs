//! Signal-processing cores shared by the stages and the simulator.

pub mod analog_filter;
pub mod spectral_filter;
pub mod spectrum;

pub use analog_filter::{AnalogFilter, FilterFamily, FilterSpec};
pub use spectral_filter::{apply_spectral, apply_table, derivative_gain, extended_len, gain_table};
pub use spectrum::{naive_dft, Spectra};
