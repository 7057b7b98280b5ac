//! Signal-processing cores shared by the stages and the simulator.

pub mod analog_filter;
pub mod spectrum;

pub use analog_filter::{AnalogFilter, FilterFamily, FilterSpec};
pub use spectrum::{naive_dft, Spectra};
