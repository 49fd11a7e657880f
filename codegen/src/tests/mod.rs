//! Tests across the stages that reach into their internals: the flexible
//! link against independent references, the scene parser fuzzed from
//! file text to emitted code, and the URDF importer fuzzed likewise.

mod flexible_link;
mod lagrange_sweeps;
mod parser_fuzz;
mod urdf_fuzz;
