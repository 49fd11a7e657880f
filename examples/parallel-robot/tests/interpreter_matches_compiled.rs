//! The interpreter against the compiled module of every robot scene of this
//! crate, bit for bit (`tests/common/interpreter_matches_compiled.rs` of the
//! repository).

#[path = "../../../tests/common/mod.rs"]
mod common;

use flexdyn_parallel_robot::scenes as compiled;

include!("../../../tests/common/interpreter_matches_compiled.rs");
