//! The control of the panic check: an index the compiler cannot bound links
//! the panic machinery, which the test must find in this program.

#![no_std]
#![no_main]

use core::hint::black_box;

use flexdyn_cortex_m_firmware::exit;
use flexdyn_runtime::nalgebra::SVector;

#[no_mangle]
fn main() -> ! {
    let v = black_box(SVector::<f64, 3>::zeros());
    black_box(v[black_box(7)]);
    exit(true)
}
