//! The properties every scene must have (`tests/common/scene_properties.rs`
//! of the repository), checked on the robot scenes of this crate: a
//! symmetric positive definite mass matrix, and every derived term equal to
//! central finite differences of the generated lower-order functions at
//! seeded random states.

#[path = "../../../tests/common/mod.rs"]
mod common;

use flexdyn_parallel_robot::scenes as compiled;

include!("../../../tests/common/scene_properties.rs");
