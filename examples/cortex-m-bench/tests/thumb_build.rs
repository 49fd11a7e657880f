//! The runtime and the generated modules of the rigid robot and of a
//! flexible scene (the spin-up beam), in f64 and in f32, build for the
//! Cortex-M4F
//! (`thumbv7em-none-eabihf`, no `std`, no allocator), and the generated
//! functions reach no panic machinery: the firmware's `terms` program calls
//! every one of them and nothing else, so its linked image (unreachable code
//! is discarded by the linker) contains no panic symbol, while the control
//! program with one unprovable index does.

use flexdyn_cortex_m_bench::{build, flash_and_ram, panic_symbols, qemu, symbols, Toolchain};

#[test]
fn generated_functions_build_for_cortex_m4f_without_panic_paths() {
    let tc = Toolchain::find().unwrap_or_else(|e| panic!("{e}"));
    let dir = build(&tc).unwrap_or_else(|e| panic!("{e}"));
    let terms = dir.join("terms");

    let found = panic_symbols(&terms).unwrap();
    assert!(
        found.is_empty(),
        "the generated functions reach the panic machinery: {found:?}"
    );
    let control = panic_symbols(&dir.join("panic_control")).unwrap();
    assert!(
        !control.is_empty(),
        "the check finds no panic machinery in the control program"
    );

    // The generated functions are really in the image (one caller per
    // model and precision), and nothing allocates or keeps static state.
    let names: Vec<String> = symbols(&terms)
        .unwrap()
        .into_iter()
        .map(|s| s.name)
        .collect();
    for caller in ["rigid_f64", "beam_f64", "rigid_f32", "beam_f32"] {
        let name = format!("terms::{caller}");
        assert!(names.contains(&name), "no {name} in {names:?}");
    }
    assert!(
        !names.iter().any(|n| n.contains("__rust_alloc")),
        "{names:?}"
    );
    let (flash, ram) = flash_and_ram(&terms).unwrap();
    assert_eq!(ram, 0, "static data in the terms program");
    assert!(
        flash > 20_000,
        "only {flash} bytes of code: were the terms optimised away?"
    );

    // And they run: the program exits normally on the emulated Cortex-M4F.
    qemu(&terms).unwrap_or_else(|e| panic!("{e}"));
}
