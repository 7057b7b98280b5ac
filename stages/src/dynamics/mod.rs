//! Rigid-body dynamics of serial chains: an immutable [`Model`], a
//! preallocated [`Data`] workspace and free functions over them, one
//! algorithm per file, each cross-checked against the Lagrangian twin in
//! `lagrange.rs`.

mod agreement;
mod base_parameters;
mod base_regressor;
mod batch;
mod data;
mod decoupled;
mod forward_dynamics;
mod kinematics;
pub mod lagrange;
pub(crate) mod mjcf;
pub mod model;
mod r_factor;
mod rnea;
mod robot_file;
mod rollout;
mod stl;
mod torque_regressor;
pub(crate) mod urdf;
pub mod xml;

pub use agreement::{torque_agreement, Agreement};
pub use base_parameters::{base_parameters, is_inertial, prior_scales, BaseParameters, PHYSICAL_FLOOR};
pub use base_regressor::{
    BaseRegressor, ModelKind, RegressorModel, SpringConfig, StribeckShape, Workspace, PAYLOAD_COLUMNS,
};
pub use batch::{BatchData, Batched, LANES};
pub use data::Data;
pub use decoupled::{decoupled_names, decoupled_regressor, gravity_amplitude_offset};
pub use forward_dynamics::{cholesky_solve_in_place, forward_dynamics, try_cholesky_solve_in_place};
pub use kinematics::{end_effector_position, forward_kinematics};
pub use model::{
    Coupling, Drive, Extent, Friction, Geometry, Inertial, Joint, Limits, Model, Shape, Stribeck, DEFAULT_GAIN_REL_STD,
    LISTED,
};
pub use r_factor::RFactor;
pub use rnea::{mass_matrix, rnea, rnea_terms, Terms};
pub use robot_file::{load_robot, load_robot_with, parse_robot_file, Robot};
pub use rollout::{
    closed_loop, noise_growth, noise_std, rollout, BaseDynamics, Channels, ClosedLoop, Pid, Rollout, Stopped, Window,
};
pub use torque_regressor::{
    friction_names, inertial_parameters, parameter_names, parameter_unit, regressor, standard_parameters, upper,
    with_standard_parameters, FrictionTerms, ParameterKind, RegressorTerms, Spring,
};
pub use urdf::{load_urdf, load_urdf_with, parse_urdf, parse_urdf_with, Locks};
