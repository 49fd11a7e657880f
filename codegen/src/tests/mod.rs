//! Tests across the stages that reach into their internals: the flexible
//! link against independent references, and the scene parser fuzzed from
//! file text to emitted code.

mod flexible_link;
mod lagrange_sweeps;
mod parser_fuzz;
