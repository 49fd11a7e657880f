//! Issue 2: properties every scene of `scenes/` must have (the checks are in
//! `common/scene_properties.rs`, shared with the parallel-robot example's
//! scenes): a symmetric positive definite mass matrix, and every derived
//! term equal to central finite differences of the generated lower-order
//! functions at seeded random states.

mod common;

use flexdyn::scenes as compiled;

include!("common/scene_properties.rs");
