//! Stage 7, emit: one Rust module per scene, built with `quote` from the
//! functions of the schedule stage, one program each
//! ([`crate::schedule::functions`]; never from scene text), and formatted
//! with `prettyplease`. The module names the runtime crate (its `Model`
//! trait, `math` and `nalgebra` re-export) by the path the builder was given.

use proc_macro2::{Literal, TokenStream};
use quote::{format_ident, quote};

use crate::derive::Equations;
use crate::expr::{Graph, Id, Symbol};
use crate::model::{Model, Precision};
use crate::schedule::{Code, Function, OpCount, Program, Shape, Stmt};

/// Operation counts of one emitted function.
#[derive(Debug, Clone, PartialEq)]
pub struct FunctionReport {
    /// Function name.
    pub name: &'static str,
    /// Its operations.
    pub ops: OpCount,
}

/// The emitted module of one scene.
#[derive(Debug, Clone)]
pub struct Emitted {
    /// Formatted source, `@generated` header first.
    pub source: String,
    /// Per-function operation counts.
    pub functions: Vec<FunctionReport>,
}

/// Name of the model struct for a scene name: `double_pendulum` -> `DoublePendulum`.
pub fn struct_name(scene: &str) -> String {
    scene
        .split('_')
        .filter(|p| !p.is_empty())
        .map(|p| {
            let mut c = p.chars();
            c.next()
                .map(|f| f.to_ascii_uppercase().to_string() + c.as_str())
                .unwrap_or_default()
        })
        .collect()
}

/// How a function's inputs are named in its signature.
#[derive(Clone, Copy)]
struct Inputs {
    q: bool,
    qd: bool,
    qdd: bool,
    t: bool,
}

struct Emitter<'a> {
    graph: &'a Graph,
    model: &'a Model,
    reports: Vec<FunctionReport>,
    perturbation: Option<&'a CoefficientPerturbation>,
    perturbed: bool,
}

/// A deliberate error in one emitted coefficient, for tests only: it proves
/// that the validation against CasADi catches a wrong term in the generated
/// code itself (see `Builder::perturb_coefficient`).
#[derive(Debug, Clone, PartialEq)]
pub struct CoefficientPerturbation {
    /// Scene whose module is perturbed.
    pub scene: String,
    /// Emitted function (`mass_matrix`, `bias`, ...).
    pub function: String,
    /// Which coefficient of that function's program: the `index`-th
    /// coefficient of a sum, counting statements in order, then outputs.
    pub index: usize,
    /// The coefficient is multiplied by `1 + relative`.
    pub relative: f64,
}

/// Multiply the `index`-th sum coefficient of `p` by `factor`; `false` when
/// the program has fewer coefficients.
fn scale_coefficient(p: &mut Program, index: usize, factor: f64) -> bool {
    fn visit(c: &mut Code, left: &mut usize, factor: f64) -> bool {
        match c {
            Code::Sum { terms, .. } => terms.iter_mut().any(|(k, t)| {
                if *left == 0 {
                    *k *= factor;
                    return true;
                }
                *left -= 1;
                visit(t, left, factor)
            }),
            Code::Prod { num, den } => num
                .iter_mut()
                .chain(den.iter_mut())
                .any(|f| visit(f, left, factor)),
            Code::Call(_, x) => visit(x, left, factor),
            Code::Atan2(y, x) => visit(y, left, factor) || visit(x, left, factor),
            Code::Var(_) | Code::Sym(_) | Code::Lit(_) => false,
        }
    }
    let mut left = index;
    p.stmts
        .iter_mut()
        .map(|s| match s {
            Stmt::Let { value, .. } => value,
            Stmt::SinCos { arg, .. } => arg,
        })
        .chain(p.outputs.iter_mut())
        .any(|c| visit(c, &mut left, factor))
}

/// The literal `x` in `precision`: for `f32` the shortest text of the
/// nearest `f32`, so that the compiler rounds once.
fn lit(x: f64, precision: Precision) -> TokenStream {
    let text = match precision {
        Precision::F64 => format!("{:?}", x.abs()),
        Precision::F32 => format!("{:?}", x.abs() as f32),
    };
    let l: Literal = text
        .parse()
        .unwrap_or_else(|_| Literal::f64_unsuffixed(x.abs()));
    if x.is_sign_negative() && x != 0.0 {
        quote!(-#l)
    } else {
        quote!(#l)
    }
}

fn usize_lit(i: usize) -> Literal {
    Literal::usize_unsuffixed(i)
}

/// Programs with at most this many statements are emitted as one `let` per
/// statement (see `Emitter::stmts`).
const FLAT_STATEMENTS: usize = 512;

/// Variables per declaration in longer programs.
const DECLARATION_GROUP: usize = 64;

/// Precedence classes for parenthesising.
const SUM: u8 = 1;
const PRODUCT: u8 = 2;
const ATOM: u8 = 3;

impl Emitter<'_> {
    fn lit(&self, x: f64) -> TokenStream {
        lit(x, self.model.precision)
    }

    /// The scalar type, `f64` or `f32`.
    fn real(&self) -> proc_macro2::Ident {
        format_ident!("{}", self.model.precision.rust_type())
    }

    fn param_ident(&self, i: u32) -> proc_macro2::Ident {
        format_ident!("{}", self.model.runtime_parameters[i as usize].name)
    }

    fn precedence(c: &Code) -> u8 {
        match c {
            Code::Sum { .. } => SUM,
            Code::Prod { .. } => PRODUCT,
            Code::Lit(x) if *x < 0.0 => SUM,
            _ => ATOM,
        }
    }

    /// Tokens for `c`, parenthesised when its precedence is below `need`.
    fn code(&self, c: &Code, need: u8) -> TokenStream {
        let body = match c {
            Code::Var(v) => {
                let id = format_ident!("v{}", v);
                quote!(#id)
            }
            Code::Sym(Symbol::Q(i)) => {
                let i = usize_lit(*i as usize);
                quote!(q[#i])
            }
            Code::Sym(Symbol::Qd(i)) => {
                let i = usize_lit(*i as usize);
                quote!(qd[#i])
            }
            Code::Sym(Symbol::Qdd(i)) => {
                let i = usize_lit(*i as usize);
                quote!(qdd[#i])
            }
            Code::Sym(Symbol::Time) => quote!(t),
            Code::Sym(Symbol::Param(i)) => {
                let p = self.param_ident(*i);
                quote!(self.#p)
            }
            Code::Lit(x) => self.lit(*x),
            Code::Sum { constant, terms } => self.sum(*constant, terms),
            Code::Prod { num, den } => {
                let num_t: Vec<TokenStream> = num.iter().map(|f| self.code(f, ATOM)).collect();
                let numerator = join_mul(quote!(1.0), &num_t);
                match den.as_slice() {
                    [] => numerator,
                    [d] => {
                        let d = self.code(d, ATOM);
                        quote!(#numerator / #d)
                    }
                    _ => {
                        let den_t: Vec<TokenStream> =
                            den.iter().map(|f| self.code(f, ATOM)).collect();
                        let d = join_mul(quote!(1.0), &den_t);
                        quote!(#numerator / (#d))
                    }
                }
            }
            Code::Call(f, a) => {
                let name = format_ident!("{}", f.name());
                let a = self.code(a, SUM);
                quote!(math::#name(#a))
            }
            Code::Atan2(y, x) => {
                let y = self.code(y, SUM);
                let x = self.code(x, SUM);
                quote!(math::atan2(#y, #x))
            }
        };
        if Self::precedence(c) < need {
            quote!((#body))
        } else {
            body
        }
    }

    fn term(&self, coef: f64, t: &Code) -> TokenStream {
        let a = coef.abs();
        if a == 1.0 {
            self.code(t, PRODUCT)
        } else {
            let l = self.lit(a);
            let t = self.code(t, PRODUCT);
            quote!(#l * #t)
        }
    }

    fn sum(&self, constant: f64, terms: &[(f64, Code)]) -> TokenStream {
        let pos: Vec<&(f64, Code)> = terms.iter().filter(|(c, _)| *c > 0.0).collect();
        let neg: Vec<&(f64, Code)> = terms.iter().filter(|(c, _)| *c < 0.0).collect();
        let mut out = TokenStream::new();
        let mut first = true;
        for (c, t) in &pos {
            let tt = self.term(*c, t);
            if first {
                out = tt;
                first = false;
            } else {
                out = quote!(#out + #tt);
            }
        }
        if first && constant != 0.0 {
            out = self.lit(constant);
            first = false;
        } else if constant > 0.0 {
            let l = self.lit(constant);
            out = quote!(#out + #l);
        } else if constant < 0.0 {
            let l = self.lit(-constant);
            out = quote!(#out - #l);
        }
        for (c, t) in &neg {
            let tt = self.term(*c, t);
            if first {
                out = quote!(-#tt);
                first = false;
            } else {
                out = quote!(#out - #tt);
            }
        }
        out
    }

    /// The statements of a program (the sines and cosines of angles that
    /// read inputs only first, see below): one `let` each, or, in programs longer
    /// than [`FLAT_STATEMENTS`], variables declared up front in groups of
    /// [`DECLARATION_GROUP`] (`let [v0, v1, ...]: [f64; 64];`) and then
    /// assigned. Every `let` opens a lexical
    /// scope nested in the previous one, and LLVM builds the debug
    /// information of nested scopes recursively: a 4282-statement function
    /// overflowed rustc's stack in debug builds.
    fn stmts(&self, p: &Program) -> TokenStream {
        let mut out = TokenStream::new();
        let flat = p.stmts.len() <= FLAT_STATEMENTS;
        if !flat {
            let vars: Vec<proc_macro2::Ident> = p
                .stmts
                .iter()
                .flat_map(|s| match s {
                    Stmt::Let { var, .. } => vec![*var],
                    Stmt::SinCos { sin, cos, .. } => vec![*sin, *cos],
                })
                .map(|v| format_ident!("v{}", v))
                .collect();
            for group in vars.chunks(DECLARATION_GROUP) {
                let n = usize_lit(group.len());
                let real = self.real();
                out.extend(quote!(let [#(#group),*]: [#real; #n];));
            }
        }
        let bind = if flat { quote!(let) } else { quote!() };
        // In f64, the sines and cosines of the angles that read inputs only
        // come first, all from one `math::sin_cos_array` call (bitwise
        // `sin_cos` lane by lane, two lanes per SIMD instruction).
        let batched = |s: &Stmt| {
            self.model.precision == Precision::F64
                && matches!(s, Stmt::SinCos { arg, .. } if !arg.reads_variables())
        };
        let (mut pairs, mut args) = (Vec::new(), Vec::new());
        for s in p.stmts.iter().filter(|s| batched(s)) {
            if let Stmt::SinCos { sin, cos, arg } = s {
                let (s, c) = (format_ident!("v{}", sin), format_ident!("v{}", cos));
                pairs.push(quote!((#s, #c)));
                args.push(self.code(arg, SUM));
            }
        }
        if !pairs.is_empty() {
            out.extend(quote!(#bind [#(#pairs),*] = math::sin_cos_array([#(#args),*]);));
        }
        for s in p.stmts.iter().filter(|s| !batched(s)) {
            out.extend(match s {
                Stmt::Let { var, value } => {
                    let v = format_ident!("v{}", var);
                    let e = self.code(value, SUM);
                    quote!(#bind #v = #e;)
                }
                Stmt::SinCos { sin, cos, arg } => {
                    let s = format_ident!("v{}", sin);
                    let c = format_ident!("v{}", cos);
                    let a = self.code(arg, SUM);
                    quote!(#bind (#s, #c) = math::sin_cos(#a);)
                }
            });
        }
        out
    }

    /// Which inputs a set of expressions reads.
    fn inputs(&self, ids: &[Id]) -> Inputs {
        let syms = self.graph.symbols(ids);
        Inputs {
            q: syms.iter().any(|s| matches!(s, Symbol::Q(_))),
            qd: syms.iter().any(|s| matches!(s, Symbol::Qd(_))),
            qdd: syms.iter().any(|s| matches!(s, Symbol::Qdd(_))),
            t: syms.contains(&Symbol::Time),
        }
    }

    /// Record the operation count of function `name`, and apply the
    /// test-only perturbation when it targets this function.
    fn record(&mut self, name: &'static str, p: &mut Program) {
        self.reports.push(FunctionReport { name, ops: p.ops });
        if let Some(c) = self.perturbation.filter(|c| c.function == name) {
            self.perturbed |= scale_coefficient(p, c.index, 1.0 + c.relative);
        }
    }

    /// A function writing one or more outputs (vectors or matrices) from its
    /// program. A matrix whose entries are not all computed is zeroed first;
    /// symmetric matrices mirror their upper triangle.
    fn function(&mut self, f: &mut Function) -> TokenStream {
        let nq = usize_lit(self.model.nq());
        self.record(f.sig.name, &mut f.program);
        let (sig, outputs, slots, p) = (&f.sig, &f.outputs, &f.slots, &f.program);
        let used = self.inputs(&f.ids);
        let body = self.stmts(p);
        let real = self.real();
        let mut assigns = TokenStream::new();
        let mut args = TokenStream::new();
        for (k, o) in outputs.iter().enumerate() {
            let name = format_ident!("{}", o.name);
            let count = slots.iter().filter(|s| s.0 == k).count();
            let arg = if count == 0 {
                format_ident!("_{}", o.name)
            } else {
                name.clone()
            };
            match o.shape {
                Shape::Vector => {
                    let len = usize_lit(o.entries.first().map_or(0, Vec::len));
                    args.extend(quote!(#arg: &mut SVector<#real, #len>,));
                }
                Shape::Matrix { symmetric } => {
                    let rows = o.entries.len();
                    let cols = self.model.nq();
                    let (r, c) = (usize_lit(rows), usize_lit(cols));
                    args.extend(quote!(#arg: &mut SMatrix<#real, #r, #c>,));
                    let full = if symmetric {
                        rows * (rows + 1) / 2
                    } else {
                        rows * cols
                    };
                    if count > 0 && count < full {
                        assigns.extend(quote!(*#name = SMatrix::zeros();));
                    }
                }
            }
        }
        for (c, &(k, i, j)) in p.outputs.iter().zip(slots) {
            let name = format_ident!("{}", outputs[k].name);
            let e = self.code(c, SUM);
            let (il, jl) = (usize_lit(i), usize_lit(j));
            match outputs[k].shape {
                Shape::Vector => assigns.extend(quote!(#name[#jl] = #e;)),
                Shape::Matrix { symmetric } => {
                    assigns.extend(quote!(#name[(#il, #jl)] = #e;));
                    if symmetric && i != j {
                        assigns.extend(quote!(#name[(#jl, #il)] = #name[(#il, #jl)];));
                    }
                }
            }
        }
        let (q, qd, t) = input_idents(used);
        let fname = format_ident!("{}", sig.name);
        let doc = sig.doc;
        let (ret, tail) = optional_output(sig.optional);
        let qd_arg = if sig.with_qd {
            quote!(#qd: &SVector<#real, #nq>,)
        } else {
            quote!()
        };
        let qdd_arg = if sig.with_qdd {
            let qdd = if used.qdd {
                format_ident!("qdd")
            } else {
                format_ident!("_qdd")
            };
            quote!(#qdd: &SVector<#real, #nq>,)
        } else {
            quote!()
        };
        quote! {
            #[doc = #doc]
            #[inline]
            fn #fname(&self, #q: &SVector<#real, #nq>, #qd_arg #qdd_arg #t: #real, #args) #ret {
                #body
                #assigns
                #tail
            }
        }
    }

    /// A function returning one scalar from its program.
    fn scalar_fn(&mut self, f: &mut Function) -> TokenStream {
        let nq = usize_lit(self.model.nq());
        self.record(f.sig.name, &mut f.program);
        let (name, doc, with_qd, p) = (f.sig.name, f.sig.doc, f.sig.with_qd, &f.program);
        let used = self.inputs(&f.ids);
        let body = self.stmts(p);
        let e = self.code(&p.outputs[0], SUM);
        let (q, qd, t) = input_idents(used);
        let fname = format_ident!("{}", name);
        let real = self.real();
        let qd_arg = if with_qd {
            quote!(#qd: &SVector<#real, #nq>,)
        } else {
            quote!()
        };
        quote! {
            #[doc = #doc]
            #[inline]
            fn #fname(&self, #q: &SVector<#real, #nq>, #qd_arg #t: #real) -> #real {
                #body
                #e
            }
        }
    }
}

/// `a * b * c` from factor tokens (the `seed` is used when there are none).
fn join_mul(seed: TokenStream, factors: &[TokenStream]) -> TokenStream {
    let mut it = factors.iter();
    let Some(first) = it.next() else {
        return seed;
    };
    let mut out = first.clone();
    for f in it {
        out = quote!(#out * #f);
    }
    out
}

/// Optional outputs override a trait method that returns whether the output
/// was generated.
fn optional_output(optional: bool) -> (TokenStream, TokenStream) {
    if optional {
        (quote!(-> bool), quote!(true))
    } else {
        (quote!(), quote!())
    }
}

fn input_idents(used: Inputs) -> (proc_macro2::Ident, proc_macro2::Ident, proc_macro2::Ident) {
    let name = |used: bool, n: &str| {
        if used {
            format_ident!("{}", n)
        } else {
            format_ident!("_{}", n)
        }
    };
    (name(used.q, "q"), name(used.qd, "qd"), name(used.t, "t"))
}

/// Emit the module of a scene, naming the runtime crate by `runtime`, with
/// an optional test-only perturbation of one coefficient; also says whether
/// the perturbation found its coefficient.
pub fn emit(
    model: &Model,
    eq: &Equations,
    functions: Vec<Function>,
    runtime: &syn::Path,
    perturbation: Option<&CoefficientPerturbation>,
) -> (Emitted, bool) {
    let mut e = Emitter {
        graph: &model.graph,
        model,
        reports: Vec::new(),
        perturbation,
        perturbed: false,
    };
    let n = model.nq();
    let nc = model.constraints.len();
    let nu = model.actuators.len();
    let (nq_l, nc_l, nu_l) = (usize_lit(n), usize_lit(nc), usize_lit(nu));
    let sname = format_ident!("{}", struct_name(&model.name));
    let real = e.real();
    let scene = model.name.as_str();

    // The trait's functions, then the optional outputs (the trait's
    // methods default to "not generated").
    let (mut core, mut scalars, mut optional) =
        (TokenStream::new(), TokenStream::new(), TokenStream::new());
    for mut f in functions {
        if f.is_scalar() {
            scalars.extend(e.scalar_fn(&mut f));
        } else if f.sig.optional {
            optional.extend(e.function(&mut f));
        } else {
            core.extend(e.function(&mut f));
        }
    }

    // Actuator map: constant.
    let mut b_assigns = TokenStream::new();
    let any_actuator = nu > 0;
    if any_actuator {
        b_assigns.extend(quote!(*b = SMatrix::zeros();));
    }
    for (i, row) in eq.actuator_map.iter().enumerate() {
        for (j, &g) in row.iter().enumerate() {
            if g != 0.0 {
                let (il, jl) = (usize_lit(i), usize_lit(j));
                let l = lit(g, model.precision);
                b_assigns.extend(quote!(b[(#il, #jl)] = #l;));
            }
        }
    }
    let b_arg = if any_actuator { quote!(b) } else { quote!(_b) };

    let coords = model.coordinates.iter().map(|c| c.name.as_str());
    let acts = model.actuators.iter().map(|a| a.name.as_str());
    let fields = model.runtime_parameters.iter().map(|p| {
        let id = format_ident!("{}", p.name);
        let doc = format!("Runtime parameter (nominal value {:?}).", p.value);
        quote!(#[doc = #doc] pub #id: #real,)
    });
    let defaults = model.runtime_parameters.iter().map(|p| {
        let id = format_ident!("{}", p.name);
        let v = lit(p.value, model.precision);
        quote!(#id: #v,)
    });
    let struct_doc = format!(
        "Equations of motion of scene `{scene}`: {n} coordinates, {nc} constraints, {nu} actuators. Fields are the runtime parameters."
    );
    let parameters = if model.runtime_parameters.is_empty() {
        quote!()
    } else {
        let names = model.runtime_parameters.iter().map(|p| p.name.as_str());
        let arms = model.runtime_parameters.iter().map(|p| {
            let id = format_ident!("{}", p.name);
            let name = p.name.as_str();
            quote!(#name => self.#id = value,)
        });
        quote! {
            const PARAMETERS: &'static [&'static str] = &[#(#names),*];
            fn set_parameter(&mut self, name: &str, value: #real) -> bool {
                match name {
                    #(#arms)*
                    _ => return false,
                }
                true
            }
        }
    };
    let struct_def = if model.runtime_parameters.is_empty() {
        quote! {
            #[doc = #struct_doc]
            #[derive(Debug, Clone, Copy, Default, PartialEq)]
            pub struct #sname;
        }
    } else {
        quote! {
            #[doc = #struct_doc]
            #[derive(Debug, Clone, Copy, PartialEq)]
            pub struct #sname { #(#fields)* }

            impl Default for #sname {
                fn default() -> Self {
                    Self { #(#defaults)* }
                }
            }
        }
    };
    let lints = quote! {
        #[allow(
            clippy::approx_constant,
            clippy::excessive_precision,
            clippy::too_many_lines,
            clippy::unreadable_literal,
            clippy::neg_multiply,
            clippy::identity_op,
            clippy::suspicious_operation_groupings,
            clippy::too_many_arguments,
            unused_parens
        )]
    };
    let consts = quote! {
        const NAME: &'static str = #scene;
        const COORDINATES: [&'static str; #nq_l] = [#(#coords),*];
        const ACTUATORS: [&'static str; #nu_l] = [#(#acts),*];
    };
    let members = quote! {
        #consts
        #core
        #[inline]
        fn actuator_map(&self, #b_arg: &mut SMatrix<#real, #nq_l, #nu_l>) {
            #b_assigns
        }
        #scalars
        #parameters
        #optional
    };
    // The runtime's trait, in the model's scalar type (`f64`, the trait's
    // default, left out).
    let (math, implementation) = match model.precision {
        Precision::F64 => (
            quote!(use #runtime::math;),
            quote!(impl #runtime::Model<#nq_l, #nc_l, #nu_l> for #sname { #members }),
        ),
        Precision::F32 => (
            quote!(use #runtime::math::f32 as math;),
            quote!(impl #runtime::Model<#nq_l, #nc_l, #nu_l, f32> for #sname { #members }),
        ),
    };
    let tokens = quote! {
        #math
        use #runtime::nalgebra::{SMatrix, SVector};

        /// Number of generalized coordinates.
        pub const NQ: usize = #nq_l;
        /// Number of constraints.
        pub const NC: usize = #nc_l;
        /// Number of actuator inputs.
        pub const NU: usize = #nu_l;

        #struct_def

        #lints
        #implementation
    };
    let file: syn::File = syn::parse2(tokens).expect("emitted tokens form a valid Rust file");
    let body = prettyplease::unparse(&file);
    let mut total = OpCount::default();
    let mut header = format!(
        "// @generated by flexdyn-codegen {} from scene `{scene}`. Do not edit: edit the scene and rebuild.\n\
         // Operation counts (add / mul / div / call):\n",
        env!("CARGO_PKG_VERSION")
    );
    for r in &e.reports {
        total += r.ops;
        header.push_str(&format!(
            "//   {:<28} {:>6} {:>6} {:>6} {:>6}\n",
            r.name, r.ops.adds, r.ops.muls, r.ops.divs, r.ops.calls
        ));
    }
    header.push_str(&format!(
        "//   {:<28} {:>6} {:>6} {:>6} {:>6}\n\
         // (constraints_and_jacobian computes constraints and constraint_jacobian in one program,\n\
         // dynamics_terms mass_matrix, bias, constraint_jacobian and constraint_rhs)\n\n",
        "total", total.adds, total.muls, total.divs, total.calls
    ));
    if model.precision == Precision::F32 {
        header.push_str("// Precision f32: implements the runtime's `Model<.., f32>`.\n\n");
    }
    if let (Some(c), true) = (perturbation, e.perturbed) {
        header.push_str(&format!(
            "// TEST ONLY: coefficient {} of `{}` deliberately multiplied by 1 + {:e}.\n\n",
            c.index, c.function, c.relative
        ));
    }
    let perturbed = e.perturbed;
    (
        Emitted {
            source: header + &body,
            functions: e.reports,
        },
        perturbed,
    )
}
