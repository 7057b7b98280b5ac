//! The simulator: realistic raw lab recordings with known ground truth.
//!
//! A robot (from a robot file) follows a reference trajectory under a
//! continuous PID position loop, integrated by fixed-step RK4 at
//! `log_rate × steps_per_sample`. The measurement chain then does what a
//! lab's does: motor current through an analog anti-alias filter
//! (integrated with the robot), sampled at the log rate with optional
//! timestamp jitter and dropped samples, white Gaussian noise on current and
//! position, positions quantised to encoder counts. A torque disturbance can
//! act inside the loop (closed-loop identification).

mod config;
mod output;
mod plant;
mod run;
pub mod synthetic;
mod truth;

pub use config::{
    ControllerConfig, Disturbance, Measurement, OutputConfig, OutputFormat, PerJoint, PlantConfig, SimConfig, Timing,
};
pub use output::{provenance, write_simulation, WrittenFiles};
pub use plant::{Gains, Plant, Reference};
pub use run::{simulate, Simulation};
pub use truth::{GroundTruth, JointTruth, TruthSamples};
