//! The C interface of a generated module (opt-in, `Builder::c_interface`):
//! `extern "C"` wrappers appended to the Rust module and the matching C
//! header `<scene>.h`.
//!
//! Both are written from the generator's own data, never from scene text:
//! the list of scheduled functions (one wrapper per function, so functions
//! added to the schedule get their wrappers without changes here), the
//! model's dimensions and its runtime parameters. Names are prefixed by the
//! scene name made a C identifier ([`c_identifier`]). Conventions:
//!
//! * arrays are owned by the caller and passed as pointers, their sizes are
//!   `#define`d in the header; matrices are row-major (entry `(i, j)` of an
//!   `R x C` matrix at `[i * C + j]`);
//! * the runtime parameters are one array in the header's order
//!   (`<PREFIX>_PARAM_<name>` indices); a null pointer means the nominal
//!   values;
//! * every function returns a status code instead of panicking:
//!   `<PREFIX>_OK`, `_NULL_POINTER` (a required pointer is null; nothing is
//!   written), `_NON_FINITE` (an output is NaN or infinite: non-finite
//!   inputs or a singular configuration; the outputs are written),
//!   `_INVALID_ARGUMENT` and `_SOLVER_FAILED` (inverse dynamics);
//! * inverse dynamics goes through the runtime's `InverseDynamics` with the
//!   `NQ - NC` coordinates the caller prescribes (`<prefix>_solve_inverse_dynamics`,
//!   emitted when `NQ > NC` and the scene has actuators): `q` is the initial
//!   guess on entry (the previous call's solution, for a warm start) and the
//!   solution on return.

use proc_macro2::{Literal, TokenStream};
use quote::{format_ident, quote};

use crate::emit::struct_name;
use crate::model::Model;
use crate::schedule::{Dim, Inputs, OutputSpec, Scheduled, Shape, Spec};

/// Status codes, their names after the prefix and their meaning.
const STATUS: [(&str, i32, &str); 5] = [
    ("OK", 0, "success"),
    ("NULL_POINTER", 1, "a required pointer is null; nothing was written"),
    (
        "NON_FINITE",
        2,
        "an output is NaN or infinite (non-finite inputs or a singular configuration); outputs were written",
    ),
    (
        "INVALID_ARGUMENT",
        3,
        "a prescribed coordinate index is out of range or repeated, or a marker index out of range",
    ),
    (
        "SOLVER_FAILED",
        4,
        "the inverse-dynamics solve failed (no convergence, singular or ill-conditioned system, non-finite values)",
    ),
];

/// `name` as a C (and Rust) identifier: ASCII letters, digits and `_`, any
/// other character replaced by `_`, prefixed by `scene_` when it would
/// start with a digit or be empty.
pub fn c_identifier(name: &str) -> String {
    let s: String = name
        .chars()
        .map(|c| if c.is_ascii_alphanumeric() { c } else { '_' })
        .collect();
    if s.is_empty() || s.starts_with(|c: char| c.is_ascii_digit()) {
        format!("scene_{s}")
    } else {
        s
    }
}

/// An unsuffixed integer literal (`12`, not `12usize`).
fn n(x: usize) -> Literal {
    Literal::usize_unsuffixed(x)
}

/// Text safe inside a C block comment.
fn comment(text: &str) -> String {
    text.replace("*/", "* /")
}

/// One scheduled function, as the C interface sees it: its table entry and
/// the `(rows, columns)` of each output.
struct Wrapped {
    spec: &'static Spec,
    shapes: Vec<(usize, usize)>,
}

impl Wrapped {
    /// The arrays the function reads, in order, with their lengths: `q`,
    /// `qd` and `qdd` or the forces `f` (NQ), the actuator inputs `tau` (NU).
    fn inputs(&self) -> &'static [(&'static str, Dim)] {
        const Q: (&str, Dim) = ("q", Dim::Coordinates);
        const QD: (&str, Dim) = ("qd", Dim::Coordinates);
        match self.spec.inputs {
            Inputs::Constant => &[],
            Inputs::Actuation => &[("tau", Dim::Actuators)],
            Inputs::Positions => &[Q],
            Inputs::Velocities => &[Q, QD],
            Inputs::Accelerations => &[Q, QD, ("qdd", Dim::Coordinates)],
            Inputs::Forces => &[Q, QD, ("f", Dim::Coordinates)],
        }
    }

    /// Whether it takes the time `t` (every function that reads a state).
    fn timed(&self) -> bool {
        !matches!(self.spec.inputs, Inputs::Constant | Inputs::Actuation)
    }

    /// Whether it returns one value (written to `out`).
    fn is_scalar(&self) -> bool {
        matches!(
            self.spec.outputs,
            [OutputSpec {
                shape: Shape::Scalar,
                ..
            }]
        )
    }
}

/// The C interface of one scene.
pub struct CInterface {
    prefix: String,
    scene: String,
    struct_name: String,
    nq: usize,
    nc: usize,
    nu: usize,
    coordinates: Vec<String>,
    markers: Vec<String>,
    parameters: Vec<(String, f64)>,
    functions: Vec<Wrapped>,
}

impl CInterface {
    /// The interface of `model` with its scheduled `functions` (before they
    /// are emitted).
    pub fn new(model: &Model, functions: &[Scheduled]) -> CInterface {
        let nq = model.nq();
        // A per-marker function is scheduled once per marker, and wrapped
        // once (with the marker index).
        let functions = functions
            .chunk_by(|a, b| a.function == b.function)
            .map(|group| &group[0])
            .map(|f| Wrapped {
                spec: f.spec(),
                shapes: f
                    .spec()
                    .outputs
                    .iter()
                    .map(|o| o.shape.size(f.dims))
                    .collect(),
            })
            .collect();
        CInterface {
            prefix: c_identifier(&model.name),
            scene: model.name.clone(),
            struct_name: struct_name(&model.name),
            nq,
            nc: model.constraints.len(),
            nu: model.actuators.len(),
            coordinates: model.coordinates.iter().map(|c| c.name.clone()).collect(),
            markers: model.markers.iter().map(|m| m.name.clone()).collect(),
            parameters: model
                .runtime_parameters
                .iter()
                .map(|p| (p.name.clone(), p.value))
                .collect(),
            functions,
        }
    }

    fn upper(&self) -> String {
        self.prefix.to_ascii_uppercase()
    }

    /// Whether the runtime's inverse dynamics is wrapped.
    fn has_inverse(&self) -> bool {
        self.nq > self.nc && self.nu > 0
    }

    /// The Rust wrappers, to append to the module (which names the runtime
    /// by `runtime`).
    pub fn rust(&self, runtime: &syn::Path) -> String {
        let s = format_ident!("{}", self.struct_name);
        let (nq, nc, nu) = (n(self.nq), n(self.nc), n(self.nu));
        let model_trait = quote!(#runtime::Model<#nq, #nc, #nu>);
        let fields = self.parameters.iter().enumerate().map(|(i, (name, _))| {
            let f = format_ident!("{}", name);
            let i = n(i);
            quote!(#f: unsafe { *params.add(#i) },)
        });
        let c_model = if self.parameters.is_empty() {
            quote!(unsafe fn c_model(_params: *const f64) -> #s { #s })
        } else {
            quote! {
                unsafe fn c_model(params: *const f64) -> #s {
                    if params.is_null() {
                        #s::default()
                    } else {
                        #s { #(#fields)* }
                    }
                }
            }
        };
        let status = STATUS.iter().map(|(name, value, doc)| {
            let id = format_ident!("C_{}", name);
            let doc = format!("C status code: {doc}.");
            let value = Literal::i32_unsuffixed(*value);
            quote!(#[doc = #doc] pub const #id: i32 = #value;)
        });
        let mut wrappers: Vec<TokenStream> = self
            .functions
            .iter()
            .map(|f| self.wrapper(f, &s, &model_trait))
            .collect();
        if self.has_inverse() {
            wrappers.push(self.inverse(runtime));
        }
        let tokens = quote! {
            #(#status)*

            /// The model with the parameters at `params` (the header's
            /// order), or the nominal ones when it is null.
            #c_model

            /// The `N` doubles at `p` as a vector.
            unsafe fn c_read<const N: usize>(p: *const f64) -> SVector<f64, N> {
                SVector::from_fn(|i, _| unsafe { *p.add(i) })
            }

            /// Writes `m` row-major to `out`; whether every entry is finite.
            unsafe fn c_write<const R: usize, const C: usize>(m: &SMatrix<f64, R, C>, out: *mut f64) -> bool {
                for (k, x) in m.transpose().iter().enumerate() {
                    unsafe { *out.add(k) = *x };
                }
                m.iter().all(|x| x.is_finite())
            }

            #(#wrappers)*
        };
        let file: syn::File = syn::parse2(tokens).expect("C wrappers form valid Rust");
        format!(
            "\n// The C interface (see {}.h).\n{}",
            self.scene,
            prettyplease::unparse(&file)
        )
    }

    /// The exported C function `item` (`pub unsafe extern "C" fn ...`) with
    /// its docs: `doc`, then the `# Safety` section naming the sizes of its
    /// `arrays`.
    fn export(doc: &str, arrays: &str, item: TokenStream) -> TokenStream {
        let safety = format!(
            " Every pointer must be null (answered by `C_NULL_POINTER`) or point to as many \
             doubles as the header says ({arrays}); `params`, when not null, to the parameters."
        );
        quote! {
            #[doc = #doc]
            #[doc = ""]
            #[doc = " # Safety"]
            #[doc = ""]
            #[doc = #safety]
            #[no_mangle]
            #item
        }
    }

    fn wrapper(
        &self,
        f: &Wrapped,
        s: &proc_macro2::Ident,
        model_trait: &TokenStream,
    ) -> TokenStream {
        let cname = format_ident!("{}_{}", self.prefix, f.spec.name);
        let method = format_ident!("{}", f.spec.name);
        let doc = format!(" {} C: `{}`.", f.spec.doc, self.c_signature(f));
        let arrays = "`q`, `qd`, `qdd`, `f`: NQ; `tau`: NU; each output its size";
        // The arrays the function reads, in order, then its time.
        let inputs: Vec<proc_macro2::Ident> = f
            .inputs()
            .iter()
            .map(|(name, _)| format_ident!("{}", name))
            .collect();
        let time = if f.timed() {
            (quote!(t: f64,), quote!(t,))
        } else {
            (quote!(), quote!())
        };
        let (t_arg, t_pass) = time;
        let outputs: Vec<(proc_macro2::Ident, usize)> = if f.is_scalar() {
            vec![(format_ident!("out"), 1)]
        } else {
            let sizes = f.shapes.iter().map(|(r, c)| r * c);
            let names = f.spec.outputs.iter().map(|o| format_ident!("{}", o.name));
            names.zip(sizes).collect()
        };
        let nulls: Vec<TokenStream> = inputs
            .iter()
            .chain(outputs.iter().filter(|(_, len)| *len > 0).map(|(id, _)| id))
            .map(|id| quote!(#id.is_null()))
            .collect();
        let null = if nulls.is_empty() {
            quote!()
        } else {
            quote!(if #(#nulls)||* {
                return C_NULL_POINTER;
            })
        };
        let dims = (self.nq, self.nc, self.nu);
        let reads: TokenStream = inputs
            .iter()
            .zip(f.inputs())
            .map(|(input, (_, dim))| {
                let len = n(dim.size(dims));
                quote!(let #input = unsafe { c_read::<#len>(#input) };)
            })
            .collect();
        let (marker_arg, marker_pass) = if f.spec.per_marker {
            (quote!(marker: usize,), quote!(marker,))
        } else {
            (quote!(), quote!())
        };
        let pass = quote!(#marker_pass #(&#inputs,)* #t_pass);
        let args = outputs.iter().map(|(id, _)| quote!(#id: *mut f64,));
        let item = if f.is_scalar() {
            quote! {
                pub unsafe extern "C" fn #cname(params: *const f64, #(#inputs: *const f64,)* #t_arg #(#args)*) -> i32 {
                    #null
                    let model = unsafe { c_model(params) };
                    #reads
                    let value = <#s as #model_trait>::#method(&model, #pass);
                    unsafe { *out = value };
                    if value.is_finite() { C_OK } else { C_NON_FINITE }
                }
            }
        } else {
            let locals = f.spec.outputs.iter().zip(&f.shapes).map(|(o, &(r, c))| {
                let local = format_ident!("{}_", o.name);
                let (r, c) = (n(r), n(c));
                match o.shape {
                    Shape::Vector(_) => quote!(let mut #local = SVector::<f64, #r>::zeros();),
                    _ => quote!(let mut #local = SMatrix::<f64, #r, #c>::zeros();),
                }
            });
            let locals_pass = f.spec.outputs.iter().map(|o| {
                let local = format_ident!("{}_", o.name);
                quote!(&mut #local,)
            });
            let call = quote!(<#s as #model_trait>::#method(&model, #pass #(#locals_pass)*));
            // Optional outputs return `true` (generated); a per-marker
            // function `false` for a marker the scene does not have.
            let call = if f.spec.per_marker {
                quote!(if !#call {
                    return C_INVALID_ARGUMENT;
                })
            } else if f.spec.optional {
                quote!(let _ = #call;)
            } else {
                quote!(#call;)
            };
            let writes = f.spec.outputs.iter().map(|o| {
                let (id, local) = (format_ident!("{}", o.name), format_ident!("{}_", o.name));
                quote!(finite &= unsafe { c_write(&#local, #id) };)
            });
            quote! {
                pub unsafe extern "C" fn #cname(params: *const f64, #marker_arg #(#inputs: *const f64,)* #t_arg #(#args)*) -> i32 {
                    #null
                    let model = unsafe { c_model(params) };
                    #reads
                    #(#locals)*
                    #call
                    let mut finite = true;
                    #(#writes)*
                    if finite { C_OK } else { C_NON_FINITE }
                }
            }
        };
        Self::export(&doc, arrays, item)
    }

    fn inverse(&self, runtime: &syn::Path) -> TokenStream {
        let cname = format_ident!("{}_solve_inverse_dynamics", self.prefix);
        let (nq, nc, nu) = (n(self.nq), n(self.nc), n(self.nu));
        let np = n(self.nq - self.nc);
        let doc = format!(
            " Inverse dynamics (the runtime's `InverseDynamics`, default configuration): the \
             coordinates `prescribed` (NP = NQ - NC indices) follow `p`, `v`, `a` at time `t`; \
             solves the others from `q` (initial guess on entry, solution on return) and writes \
             `qd`, `qdd`, the actuator inputs `tau` (NU) and the constraint forces `lambda` (NC). \
             C: `{}`.",
            self.inverse_signature()
        );
        let lambda_null = if self.nc > 0 {
            quote!(|| lambda.is_null())
        } else {
            quote!()
        };
        let arrays =
            "`prescribed`, `p`, `v`, `a`: NP; `q`, `qd`, `qdd`: NQ; `tau`: NU; `lambda`: NC";
        Self::export(
            &doc,
            arrays,
            quote! {
                #[allow(clippy::too_many_arguments)]
                pub unsafe extern "C" fn #cname(
                    params: *const f64,
                    prescribed: *const usize,
                    q: *mut f64,
                    t: f64,
                    p: *const f64,
                    v: *const f64,
                    a: *const f64,
                    qd: *mut f64,
                    qdd: *mut f64,
                    tau: *mut f64,
                    lambda: *mut f64,
                ) -> i32 {
                    if prescribed.is_null() || q.is_null() || p.is_null() || v.is_null() || a.is_null()
                        || qd.is_null() || qdd.is_null() || tau.is_null() #lambda_null
                    {
                        return C_NULL_POINTER;
                    }
                    let model = unsafe { c_model(params) };
                    let indices: [usize; #np] = core::array::from_fn(|i| unsafe { *prescribed.add(i) });
                    let guess = unsafe { c_read::<#nq>(q) };
                    let Ok(mut solver) = #runtime::InverseDynamics::<#nq, #nc, #nu, #np>::new(
                        indices,
                        guess,
                        #runtime::InverseConfig::default(),
                    ) else {
                        return C_INVALID_ARGUMENT;
                    };
                    let (p, v, a) = unsafe { (c_read::<#np>(p), c_read::<#np>(v), c_read::<#np>(a)) };
                    let mut sol = #runtime::InverseSolution::<#nq, #nc, #nu>::default();
                    if solver.solve(&model, t, &p, &v, &a, &mut sol).is_err() {
                        return C_SOLVER_FAILED;
                    }
                    unsafe {
                        c_write(&sol.q, q);
                        c_write(&sol.qd, qd);
                        c_write(&sol.qdd, qdd);
                        c_write(&sol.tau, tau);
                        c_write(&sol.lambda, lambda);
                    }
                    C_OK
                }
            },
        )
    }

    fn c_signature(&self, f: &Wrapped) -> String {
        let mut args = vec!["const double *params".to_owned()];
        if f.spec.per_marker {
            args.push("size_t marker".into());
        }
        args.extend(
            f.inputs()
                .iter()
                .map(|(name, _)| format!("const double *{name}")),
        );
        if f.timed() {
            args.push("double t".into());
        }
        if f.is_scalar() {
            args.push("double *out".into());
        } else {
            args.extend(f.spec.outputs.iter().map(|o| format!("double *{}", o.name)));
        }
        format!("int {}_{}({})", self.prefix, f.spec.name, args.join(", "))
    }

    fn inverse_signature(&self) -> String {
        format!(
            "int {}_solve_inverse_dynamics(const double *params, const size_t *prescribed, \
             double *q, double t, const double *p, const double *v, const double *a, \
             double *qd, double *qdd, double *tau, double *lambda)",
            self.prefix
        )
    }

    /// The C header.
    pub fn header(&self) -> String {
        let up = self.upper();
        let guard = format!("FLEXDYN_{up}_H");
        let mut h = format!(
            "/* @generated by flexdyn-codegen {}: the C interface of the generated Rust module\n   \
             {}.rs (scene `{}`). Do not edit: edit the scene and regenerate. */\n\
             #ifndef {guard}\n#define {guard}\n\n#include <stddef.h>\n\n\
             #ifdef __cplusplus\nextern \"C\" {{\n#endif\n\n",
            env!("CARGO_PKG_VERSION"),
            c_identifier(&self.scene),
            c_identifier(&self.scene),
        );
        h.push_str(
            "/* Sizes. Arrays are owned by the caller; matrices are row-major: entry (i, j)\n   \
             of an R x C matrix at [i * C + j]. */\n",
        );
        let np = if self.has_inverse() {
            self.nq - self.nc
        } else {
            0
        };
        for (name, value, doc) in [
            ("NQ", self.nq, "generalized coordinates"),
            ("NC", self.nc, "constraints"),
            ("NU", self.nu, "actuator inputs"),
            ("NPARAMS", self.parameters.len(), "runtime parameters"),
            ("NM", self.markers.len(), "markers"),
            ("NP", np, "prescribed coordinates of the inverse dynamics"),
        ] {
            h.push_str(&format!("#define {up}_{name} {value} /* {doc} */\n"));
        }
        h.push_str("\n/* Status codes returned by every function. */\n");
        for (name, value, doc) in STATUS {
            h.push_str(&format!(
                "#define {up}_{name} {value} /* {} */\n",
                comment(doc)
            ));
        }
        h.push_str("\n/* Index of each coordinate in q. */\n");
        for (i, c) in self.coordinates.iter().enumerate() {
            h.push_str(&format!("#define {up}_Q_{} {i}\n", c_identifier(c)));
        }
        if !self.markers.is_empty() {
            h.push_str("\n/* Index of each marker (the `marker` argument). */\n");
            for (i, m) in self.markers.iter().enumerate() {
                h.push_str(&format!("#define {up}_MARKER_{} {i}\n", c_identifier(m)));
            }
        }
        if !self.parameters.is_empty() {
            h.push_str(
                "\n/* Index of each runtime parameter in params (a null params means the\n   \
                 nominal values, given in the comments). */\n",
            );
            for (i, (p, v)) in self.parameters.iter().enumerate() {
                h.push_str(&format!(
                    "#define {up}_PARAM_{} {i} /* nominal {v:?} */\n",
                    c_identifier(p)
                ));
            }
        }
        h.push('\n');
        for f in &self.functions {
            let sizes = if f.is_scalar() {
                "out: one double".to_owned()
            } else {
                let sizes = f.spec.outputs.iter().zip(&f.shapes);
                let sizes: Vec<String> = sizes
                    .map(|(o, (r, c))| format!("{} {r} x {c}", o.name))
                    .collect();
                sizes.join(", ")
            };
            h.push_str(&format!(
                "/* {} ({sizes}) */\n{};\n\n",
                comment(f.spec.doc),
                self.c_signature(f)
            ));
        }
        if self.has_inverse() {
            h.push_str(&format!(
                "/* Inverse dynamics: the NP coordinates `prescribed` follow p, v, a at time t;\n   \
                 q holds the initial guess on entry (the previous solution) and the solution on\n   \
                 return; writes qd, qdd (NQ), tau (NU), lambda (NC). */\n{};\n\n",
                self.inverse_signature()
            ));
        }
        h.push_str(&format!(
            "#ifdef __cplusplus\n}}\n#endif\n\n#endif /* {guard} */\n"
        ));
        h
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_become_c_identifiers() {
        for (name, c) in [
            ("pendulum", "pendulum"),
            ("robot-2 arm", "robot_2_arm"),
            ("2dof", "scene_2dof"),
            ("", "scene_"),
            ("pend\u{fc}l", "pend_l"),
        ] {
            assert_eq!(c_identifier(name), c);
        }
        assert_eq!(comment("a */ b"), "a * / b");
    }
}
