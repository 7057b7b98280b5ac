//! Signal-processing cores shared by the stages and the simulator.

pub mod analog_filter;

pub use analog_filter::{AnalogFilter, FilterFamily, FilterSpec};
