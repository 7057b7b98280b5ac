//! A model written out for simulators: a URDF or MJCF of its own, or the
//! user's URDF or MJCF with the identified bodies and friction patched in,
//! every other byte kept. Reading robot files is `dynamics`'s; writing
//! them is this room's.

mod error;
mod mjcf;
mod mjcf_patch;
mod urdf;
mod urdf_patch;

pub use error::PatchError;
pub use mjcf::{principal_axes, to_mjcf};
pub use mjcf_patch::MjcfPatch;
pub use urdf::to_urdf;
pub use urdf_patch::{patch_urdf, Patched, UrdfPatch};
