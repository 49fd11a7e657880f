//! Regression test from issue 4 (speed work): once repeated pairs were
//! shared, the flexible robot's `bias_jacobians` had 4282 statements, one
//! `let` each. Every `let` opens a lexical scope nested in the previous
//! one, LLVM builds the debug information of nested scopes recursively, and
//! `cargo build` (debug) overflowed rustc's stack (2763 had still compiled).
//! The emitter now declares the variables of long programs in groups and
//! assigns them, so the nesting stays shallow whatever the scene's size.
//!
//! Checked on the code emitted for every shipped scene (`scenes/` and the
//! parallel-robot example's `scenes/`, generated here): no function body
//! nests more than `LIMIT` scopes.

use std::path::Path;

/// Far below the depth that crashed, and above the emitter's flat limit
/// (512 statements) plus one declaration per 64 variables.
const LIMIT: usize = 1024;

/// `let` statements directly in a block: each nests the rest of the block.
fn nesting(block: &syn::Block) -> usize {
    block
        .stmts
        .iter()
        .filter(|s| matches!(s, syn::Stmt::Local(_)))
        .count()
}

#[test]
fn emitted_functions_nest_few_scopes() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let scenes = flexdyn_codegen::Builder::new()
        .scenes_in(root.join("scenes"))
        .scenes_in(root.join("examples/parallel-robot/scenes"))
        .scene_files()
        .expect("scene folders are readable");
    let mut checked = 0;
    let mut deepest = (0, String::new());
    for path in &scenes {
        let text = flexdyn_codegen::generate_scene(path)
            .unwrap_or_else(|e| panic!("{e}"))
            .source;
        let file = syn::parse_file(&text).expect("generated file parses");
        for item in &file.items {
            let syn::Item::Impl(imp) = item else {
                continue;
            };
            for f in &imp.items {
                if let syn::ImplItem::Fn(f) = f {
                    let n = nesting(&f.block);
                    let name = format!("{}: {}", path.display(), f.sig.ident);
                    assert!(n <= LIMIT, "{name} nests {n} let scopes (limit {LIMIT})");
                    if n > deepest.0 {
                        deepest = (n, name);
                    }
                    checked += 1;
                }
            }
        }
    }
    assert!(
        checked > 100,
        "only {checked} functions found in {} scenes",
        scenes.len()
    );
    println!(
        "{checked} functions; deepest: {} let scopes in {}",
        deepest.0, deepest.1
    );
}
