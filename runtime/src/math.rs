//! Scalar functions used by generated code.
//!
//! With the `std` feature these call the platform's math library; without it
//! they call the pure-Rust `libm` crate, so generated code builds for
//! `no_std` targets unchanged. [`sin_cos`], the most frequent call in
//! generated code, is computed inline, the same in both cases (see its
//! documentation).

#[cfg(feature = "std")]
extern crate std;

macro_rules! unary {
    ($($(#[$doc:meta])* $name:ident => $libm:ident;)*) => {$(
        $(#[$doc])*
        #[inline(always)]
        pub fn $name(x: f64) -> f64 {
            #[cfg(feature = "std")]
            { x.$name() }
            #[cfg(not(feature = "std"))]
            { libm::$libm(x) }
        }
    )*};
}

unary! {
    /// Sine.
    sin => sin;
    /// Cosine.
    cos => cos;
    /// Tangent.
    tan => tan;
    /// Exponential.
    exp => exp;
    /// Natural logarithm.
    ln => log;
    /// Square root.
    sqrt => sqrt;
    /// Absolute value.
    abs => fabs;
}

/// `sign` and `step` of one float type, by comparisons only (no library
/// call), the same with or without `std`.
macro_rules! switches {
    ($t:ty) => {
        /// Sign: `1` for positive `x`, `-1` for negative, and `x` itself at
        /// `+-0` (zero) and for NaN (which propagates). Not `signum`, which
        /// is `1` at `+0`.
        #[inline(always)]
        pub fn sign(x: $t) -> $t {
            if x > 0.0 {
                1.0
            } else if x < 0.0 {
                -1.0
            } else {
                x
            }
        }

        /// Heaviside step `(1 + sign(x)) / 2`: `1` for positive `x`, `0` for
        /// negative, `1/2` at `+-0` (so `step(x) + step(-x) = 1` for every
        /// `x`), NaN for NaN. Exact: no rounding in any of the cases.
        #[inline(always)]
        pub fn step(x: $t) -> $t {
            0.5 * (1.0 + sign(x))
        }
    };
}

switches!(f64);

/// The inline sine and cosine of [`sin_cos`] and [`sin_cos_array`], on
/// the targets with SIMD registers of two `f64` (SSE2 on every x86-64
/// target, NEON on AArch64).
#[cfg(any(target_arch = "x86_64", target_arch = "aarch64"))]
mod inline {
    /// Largest `|x|` that [`super::sin_cos`] reduces inline: `k = round(2 x / pi)` stays
    /// below `2^20`, so that `k * PIO2_1` and `k * PIO2_2` are exact.
    const REDUCED: f64 = 1.0e6;
    /// `pi/2 = PIO2_1 + PIO2_2 + PIO2_3`; `PIO2_1` and `PIO2_2` have 33
    /// significant bits each, `PIO2_3` is the rest rounded to `f64`.
    const PIO2_1: f64 = 1.570_796_326_734_125_6;
    const PIO2_2: f64 = 6.077_100_506_303_966e-11;
    const PIO2_3: f64 = 2.022_266_248_795_950_6e-21;
    /// `1.5 * 2^52`: adding it rounds an `f64` below `2^51` in magnitude to an
    /// integer, whose low bits then sit in the low bits of the sum.
    const ROUNDING_SHIFT: f64 = 6_755_399_441_055_744.0;

    /// Arithmetic on one `f64` or on a SIMD register of several, so that the
    /// sine and cosine are written once for both ([`sin_cos_lanes`]), with
    /// bitwise the same result in every lane.
    trait Lanes:
        Copy
        + core::ops::Add<Output = Self>
        + core::ops::Sub<Output = Self>
        + core::ops::Mul<Output = Self>
    {
        /// `x` in every lane.
        fn splat(x: f64) -> Self;
        /// Bitwise exclusive or.
        fn xor(self, other: Self) -> Self;
        /// Bitwise and.
        fn and(self, other: Self) -> Self;
        /// All bits set where the integer in the low bits of `self` (see
        /// [`ROUNDING_SHIFT`]) is odd, else none.
        fn odd_mask(self) -> Self;
        /// The sign bit where bit 1 of that integer plus `offset` is set.
        fn sign_of_quadrant(self, offset: u64) -> Self;
    }

    impl Lanes for f64 {
        #[inline(always)]
        fn splat(x: f64) -> Self {
            x
        }
        #[inline(always)]
        fn xor(self, other: Self) -> Self {
            f64::from_bits(self.to_bits() ^ other.to_bits())
        }
        #[inline(always)]
        fn and(self, other: Self) -> Self {
            f64::from_bits(self.to_bits() & other.to_bits())
        }
        #[inline(always)]
        fn odd_mask(self) -> Self {
            f64::from_bits((self.to_bits() & 1).wrapping_neg())
        }
        #[inline(always)]
        fn sign_of_quadrant(self, offset: u64) -> Self {
            f64::from_bits((self.to_bits().wrapping_add(offset) & 2) << 62)
        }
    }

    /// `N` `f64` lanes, operated on element by element: the compiler makes
    /// one SIMD instruction of each two lanes' operation where the target
    /// has them (SSE2 on every x86-64 target, NEON on AArch64).
    #[derive(Clone, Copy)]
    struct Many<const N: usize>([f64; N]);

    impl<const N: usize> Many<N> {
        /// `f` of the two operands' lanes, lane by lane.
        #[inline(always)]
        fn zip(self, o: Self, f: impl Fn(f64, f64) -> f64) -> Self {
            Many(core::array::from_fn(|i| f(self.0[i], o.0[i])))
        }
    }

    macro_rules! lane_operators {
        ($($trait:ident $method:ident;)*) => {$(
            impl<const N: usize> core::ops::$trait for Many<N> {
                type Output = Self;
                #[inline(always)]
                fn $method(self, o: Self) -> Self {
                    self.zip(o, <f64 as core::ops::$trait>::$method)
                }
            }
        )*};
    }
    lane_operators! {
        Add add;
        Sub sub;
        Mul mul;
    }

    impl<const N: usize> Lanes for Many<N> {
        #[inline(always)]
        fn splat(x: f64) -> Self {
            Many([x; N])
        }
        #[inline(always)]
        fn xor(self, o: Self) -> Self {
            self.zip(o, Lanes::xor)
        }
        #[inline(always)]
        fn and(self, o: Self) -> Self {
            self.zip(o, Lanes::and)
        }
        #[inline(always)]
        fn odd_mask(self) -> Self {
            Many(self.0.map(Lanes::odd_mask))
        }
        #[inline(always)]
        fn sign_of_quadrant(self, offset: u64) -> Self {
            Many(self.0.map(|x| x.sign_of_quadrant(offset)))
        }
    }

    /// Sine and cosine, lane by lane (see [`super::sin_cos`]): `k = round(2 x / pi)`
    /// by [`ROUNDING_SHIFT`], `r = x - k pi/2` in three steps, polynomials in
    /// `z = r^2` for `sin r = r + r z P(z)` (`P` of degree 5) and `cos r = 1 + z
    /// Q(z)` (`Q` of degree 6) by Estrin's scheme (pairs of coefficients, then
    /// powers `z^2`, `z^4`: shorter chains of dependent operations than
    /// Horner's), then, without branches, `sin
    /// r` and `cos r` swapped for odd `k` and their signs flipped by quadrant.
    /// `P` and `Q` are the Taylor series economized on `z` in `[0, 0.618]`
    /// (`(pi/4)^2 = 0.617`): the terms above the kept degree replaced by
    /// Chebyshev polynomials of that interval, computed in exact rational
    /// arithmetic; errors below `2.1e-17` in `P` and `2e-19` in `Q`, far below
    /// half an ulp of the sine and cosine.
    #[inline(always)]
    fn sin_cos_lanes<L: Lanes>(x: L) -> (L, L) {
        // Highest power first.
        const SIN: [f64; 6] = [
            1.591_796_154_191_437e-10,
            -2.505_112_952_547_541_3e-8,
            2.755_731_609_147_818_6e-6,
            -1.984_126_983_673_736_7e-4,
            8.333_333_333_330_934e-3,
            -1.666_666_666_666_666_6e-1,
        ];
        const COS: [f64; 7] = [
            -1.136_787_518_659_782_7e-11,
            2.087_588_464_797_018_5e-9,
            -2.755_731_555_319_084_6e-7,
            2.480_158_729_365_573e-5,
            -1.388_888_888_888_072_8e-3,
            4.166_666_666_666_664e-2,
            -0.5,
        ];
        let shifted = x * L::splat(core::f64::consts::FRAC_2_PI) + L::splat(ROUNDING_SHIFT);
        let k = shifted - L::splat(ROUNDING_SHIFT);
        let r = ((x - k * L::splat(PIO2_1)) - k * L::splat(PIO2_2)) - k * L::splat(PIO2_3);
        let z = r * r;
        let z2 = z * z;
        let z4 = z2 * z2;
        let pair = |a: f64, b: f64| L::splat(a) * z + L::splat(b);
        let p = pair(SIN[0], SIN[1]) * z4 + (pair(SIN[2], SIN[3]) * z2 + pair(SIN[4], SIN[5]));
        let q = (L::splat(COS[0]) * z2 + pair(COS[1], COS[2])) * z4
            + (pair(COS[3], COS[4]) * z2 + pair(COS[5], COS[6]));
        let s = r + r * z * p;
        let c = L::splat(1.0) + z * q;
        let exchanged = s.xor(c).and(shifted.odd_mask());
        (
            s.xor(exchanged).xor(shifted.sign_of_quadrant(0)),
            c.xor(exchanged).xor(shifted.sign_of_quadrant(1)),
        )
    }

    /// [`super::sin_cos_array`]: up to [`ALL_AT_ONCE`] lanes as one
    /// [`Many`] (straight-line code, the compiler pairing the lanes into
    /// SIMD instructions), more two at a time (`Many<2>`) in a loop (less
    /// code for long batches).
    ///
    /// Short batches used the loop too until 2026-11-28. Where the
    /// compiler left a loop of three or more pairs rolled, it ran the lanes
    /// as scalars and passed the results through the stack, and the
    /// generated programs that called it ran up to 2x slower. The Panda's
    /// inverse dynamics, in a binary holding only that robot, took 265 ns
    /// with the loop and 134 ns with [`Many`]; TIAGo's and Solo12's forward
    /// dynamics ran about 30 % faster. TALOS's programs (27 angles) ran 8 %
    /// to 10 % slower with one [`Many`] than with the loop
    /// (docs/benchmarks.md).
    #[inline(always)]
    pub(super) fn sin_cos_array<const N: usize>(x: [f64; N]) -> [(f64, f64); N] {
        if !x.iter().all(|x| x.abs() <= REDUCED) {
            return x.map(sin_cos_out_of_line);
        }
        if N <= ALL_AT_ONCE {
            let (s, c) = sin_cos_lanes(Many(x));
            return core::array::from_fn(|i| (s.0[i], c.0[i]));
        }
        let mut out = [(0.0, 0.0); N];
        for (x, out) in x.chunks_exact(2).zip(out.chunks_exact_mut(2)) {
            let (s, c) = sin_cos_lanes(Many([x[0], x[1]]));
            out[0] = (s.0[0], c.0[0]);
            out[1] = (s.0[1], c.0[1]);
        }
        if N % 2 == 1 {
            out[N - 1] = sin_cos_lanes(x[N - 1]);
        }
        out
    }

    /// Most lanes that [`sin_cos_array`] computes as one [`Many`].
    const ALL_AT_ONCE: usize = 16;

    /// One lane of [`sin_cos_array`] when some lane is not reduced inline:
    /// [`super::sin_cos`] for the lanes that are, `libm`'s `sincos` for the
    /// others.
    #[cold]
    #[inline(never)]
    fn sin_cos_out_of_line(x: f64) -> (f64, f64) {
        if x.abs() <= REDUCED {
            super::sin_cos(x)
        } else {
            libm::sincos(x)
        }
    }
}

/// Sines and cosines of several arguments, lane by lane bitwise
/// [`sin_cos`]. On x86-64 and AArch64 computed inline, two lanes per SIMD
/// instruction (straight-line code for up to 16 lanes, a loop over pairs
/// for more); generated code computes the sines and cosines of all its
/// angles that depend on the inputs only in one call. Elsewhere (e.g. a
/// Cortex-M, whose `f64` arithmetic is emulated in software) `libm`'s
/// `sincos` lane by lane.
#[inline(always)]
pub fn sin_cos_array<const N: usize>(x: [f64; N]) -> [(f64, f64); N] {
    #[cfg(any(target_arch = "x86_64", target_arch = "aarch64"))]
    let sc = inline::sin_cos_array(x);
    #[cfg(not(any(target_arch = "x86_64", target_arch = "aarch64")))]
    let sc = x.map(libm::sincos);
    sc
}

/// Sine and cosine of one argument, computed together (one argument
/// reduction), the same with or without `std`. On x86-64 and AArch64
/// inline, in `f64` arithmetic: `x = k pi/2 + r` with `k` the nearest integer to `2 x / pi` and `r` in
/// `[-pi/4, pi/4]` (`pi/2` split into three parts, the first two with few
/// enough bits that their products with `k` are exact for `|x| <= 1e6`),
/// then the Taylor polynomials of `sin r` and `cos r` and the quadrant of
/// `k`. Larger or non-finite arguments go to `libm`'s `sincos` (out of
/// line). Within 1.5 units in the last place of `libm`'s values (tested).
/// Elsewhere `libm`'s `sincos`. [`sin_cos_array`] computes several at once,
/// bitwise the same.
#[inline(always)]
pub fn sin_cos(x: f64) -> (f64, f64) {
    let [sc] = sin_cos_array([x]);
    sc
}

/// Whether [`mul_add`] and its three siblings fuse: one rounding where the
/// build targets a processor that has fused multiply-adds and may use `std`
/// (`-C target-cpu=native` on a recent x86-64: what a C compiler contracts
/// `a * b + c` to at `-march=native`); elsewhere the expression as written
/// (two roundings; bitwise what the interpreter computes).
macro_rules! fused_or_written {
    ($(#[$doc:meta])* $name:ident($($arg:ident),*) = $fused:expr, $written:expr;) => {
        $(#[$doc])*
        #[inline(always)]
        pub fn $name($($arg: f64),*) -> f64 {
            #[cfg(all(feature = "std", target_feature = "fma"))]
            {
                $fused
            }
            #[cfg(not(all(feature = "std", target_feature = "fma")))]
            {
                $written
            }
        }
    };
}

fused_or_written! {
    /// `x * y + c`, as the generated modules write a product added to a value.
    mul_add(x, y, c) = x.mul_add(y, c), x * y + c;
}
fused_or_written! {
    /// `a + x * y`.
    add_mul(a, x, y) = x.mul_add(y, a), a + x * y;
}
fused_or_written! {
    /// `a - x * y`.
    sub_mul(a, x, y) = (-x).mul_add(y, a), a - x * y;
}
fused_or_written! {
    /// `x * y - b`.
    mul_sub(x, y, b) = x.mul_add(y, -b), x * y - b;
}

/// Two `f64` lanes, for the statements of a generated program that
/// compute the same expression for two mirror-image limbs (a humanoid's
/// legs, two fingers): each lane is bitwise the scalar expression, the
/// pair one SIMD instruction per operation on x86-64 (SSE2, in every
/// x86-64 target), which halves those statements' instructions and the
/// registers they hold. Elsewhere two scalars.
#[derive(Clone, Copy, Debug)]
pub struct F2(pair::Repr);

impl F2 {
    /// The lanes `a` and `b`.
    #[inline(always)]
    pub fn new(a: f64, b: f64) -> F2 {
        F2(pair::new(a, b))
    }
    /// The first lane.
    #[inline(always)]
    pub fn lo(self) -> f64 {
        pair::lo(self.0)
    }
    /// The second lane.
    #[inline(always)]
    pub fn hi(self) -> f64 {
        pair::hi(self.0)
    }
    /// `a + b`, lane by lane.
    #[inline(always)]
    pub fn plus(a: F2, b: F2) -> F2 {
        F2(pair::add(a.0, b.0))
    }
    /// `a - b`, lane by lane.
    #[inline(always)]
    pub fn minus(a: F2, b: F2) -> F2 {
        F2(pair::sub(a.0, b.0))
    }
    /// `a * b`, lane by lane.
    #[inline(always)]
    pub fn times(a: F2, b: F2) -> F2 {
        F2(pair::mul(a.0, b.0))
    }
    /// `a / b`, lane by lane.
    #[inline(always)]
    pub fn over(a: F2, b: F2) -> F2 {
        F2(pair::div(a.0, b.0))
    }
    /// `-a`, lane by lane (the sign bit flipped).
    #[inline(always)]
    pub fn negated(a: F2) -> F2 {
        F2(pair::neg(a.0))
    }
    /// `a` with its first lane negated (the sign bit flipped).
    #[inline(always)]
    pub fn negated_lo(a: F2) -> F2 {
        F2(pair::flip(a.0, true, false))
    }
    /// `a` with its second lane negated (the sign bit flipped).
    #[inline(always)]
    pub fn negated_hi(a: F2) -> F2 {
        F2(pair::flip(a.0, false, true))
    }
    /// [`mul_add`] lane by lane.
    #[inline(always)]
    pub fn mul_add(x: F2, y: F2, c: F2) -> F2 {
        #[cfg(all(feature = "std", target_feature = "fma"))]
        {
            F2(pair::fused(x.0, y.0, c.0))
        }
        #[cfg(not(all(feature = "std", target_feature = "fma")))]
        {
            F2::plus(F2::times(x, y), c)
        }
    }
    /// [`add_mul`] lane by lane.
    #[inline(always)]
    pub fn add_mul(a: F2, x: F2, y: F2) -> F2 {
        #[cfg(all(feature = "std", target_feature = "fma"))]
        {
            F2(pair::fused(x.0, y.0, a.0))
        }
        #[cfg(not(all(feature = "std", target_feature = "fma")))]
        {
            F2::plus(a, F2::times(x, y))
        }
    }
    /// [`sub_mul`] lane by lane.
    #[inline(always)]
    pub fn sub_mul(a: F2, x: F2, y: F2) -> F2 {
        #[cfg(all(feature = "std", target_feature = "fma"))]
        {
            F2(pair::fused(pair::neg(x.0), y.0, a.0))
        }
        #[cfg(not(all(feature = "std", target_feature = "fma")))]
        {
            F2::minus(a, F2::times(x, y))
        }
    }
    /// [`mul_sub`] lane by lane.
    #[inline(always)]
    pub fn mul_sub(x: F2, y: F2, b: F2) -> F2 {
        #[cfg(all(feature = "std", target_feature = "fma"))]
        {
            F2(pair::fused(x.0, y.0, pair::neg(b.0)))
        }
        #[cfg(not(all(feature = "std", target_feature = "fma")))]
        {
            F2::minus(F2::times(x, y), b)
        }
    }
}

/// Runs `body`, a generated function's statements, compiled for the
/// best instruction set this build may use on the processor it runs on:
/// where the build targets x86-64 without AVX (the default target), `body`
/// is compiled twice, once as the target allows and once with AVX enabled,
/// and the AVX copy runs where the processor and the operating system
/// support AVX (detected once, then cached). AVX's three-operand forms save
/// the register copies that SSE2's two-operand arithmetic needs (a fifth of
/// a generated program's instructions). Neither copy fuses a multiply with
/// an add, so both compute bitwise the same results. Elsewhere, and where
/// the build already targets AVX, `body` runs as compiled.
///
/// The generated modules pass their functions' bodies as closures marked
/// `#[inline(always)]`, so that each copy holds the whole program.
#[inline(always)]
pub fn dispatch<R>(body: impl FnOnce() -> R) -> R {
    #[cfg(all(target_arch = "x86_64", not(target_feature = "avx")))]
    if avx::available() {
        return avx::run(body);
    }
    body()
}

/// Run-time selection of AVX code ([`dispatch`]).
#[cfg(all(target_arch = "x86_64", not(target_feature = "avx")))]
#[allow(unsafe_code)]
mod avx {
    use core::arch::x86_64::{__cpuid, _xgetbv};
    use core::sync::atomic::{AtomicU8, Ordering};

    /// 0: not yet detected; 1: no AVX; 2: AVX.
    static STATE: AtomicU8 = AtomicU8::new(0);

    /// Whether the processor and the operating system support AVX.
    #[inline(always)]
    pub(super) fn available() -> bool {
        match STATE.load(Ordering::Relaxed) {
            0 => detect(),
            state => state == 2,
        }
    }

    #[cold]
    #[inline(never)]
    fn detect() -> bool {
        // CPUID leaf 1: ECX bit 28 (AVX) and bit 27 (OSXSAVE: the operating
        // system manages the extended state, so that XGETBV may be read);
        // XCR0 bits 1 and 2: the system saves the XMM and YMM registers.
        // SAFETY: leaf 1 exists on every x86-64 processor; XGETBV is read
        // only where OSXSAVE says that it is enabled.
        #[allow(unused_unsafe)]
        let ecx = unsafe { __cpuid(1) }.ecx;
        let yes =
            ecx & (1 << 27) != 0 && ecx & (1 << 28) != 0 && unsafe { xcr0() } & 0b110 == 0b110;
        STATE.store(if yes { 2 } else { 1 }, Ordering::Relaxed);
        yes
    }

    #[target_feature(enable = "xsave")]
    unsafe fn xcr0() -> u64 {
        _xgetbv(0)
    }

    /// `body` compiled with AVX enabled.
    #[inline(always)]
    pub(super) fn run<R>(body: impl FnOnce() -> R) -> R {
        // SAFETY: called only where `available` found AVX supported.
        unsafe { with_avx(body) }
    }

    #[target_feature(enable = "avx")]
    #[inline]
    unsafe fn with_avx<R>(body: impl FnOnce() -> R) -> R {
        body()
    }
}

/// [`F2`]'s lanes in one SSE2 register.
#[cfg(target_arch = "x86_64")]
#[allow(unsafe_code)]
mod pair {
    use core::arch::x86_64::{
        __m128d, _mm_add_pd, _mm_cvtsd_f64, _mm_div_pd, _mm_mul_pd, _mm_set1_pd, _mm_set_pd,
        _mm_sub_pd, _mm_unpackhi_pd, _mm_xor_pd,
    };

    pub(super) type Repr = __m128d;

    // SAFETY (every block of this module): SSE2, the one target feature
    // these intrinsics need, is part of every x86-64 target; they read and
    // write registers only.
    #[inline(always)]
    pub(super) fn new(a: f64, b: f64) -> Repr {
        unsafe { _mm_set_pd(b, a) }
    }
    #[inline(always)]
    pub(super) fn lo(x: Repr) -> f64 {
        unsafe { _mm_cvtsd_f64(x) }
    }
    #[inline(always)]
    pub(super) fn hi(x: Repr) -> f64 {
        unsafe { _mm_cvtsd_f64(_mm_unpackhi_pd(x, x)) }
    }
    #[inline(always)]
    pub(super) fn add(a: Repr, b: Repr) -> Repr {
        unsafe { _mm_add_pd(a, b) }
    }
    #[inline(always)]
    pub(super) fn sub(a: Repr, b: Repr) -> Repr {
        unsafe { _mm_sub_pd(a, b) }
    }
    #[inline(always)]
    pub(super) fn mul(a: Repr, b: Repr) -> Repr {
        unsafe { _mm_mul_pd(a, b) }
    }
    #[inline(always)]
    pub(super) fn div(a: Repr, b: Repr) -> Repr {
        unsafe { _mm_div_pd(a, b) }
    }
    #[inline(always)]
    pub(super) fn neg(a: Repr) -> Repr {
        unsafe { _mm_xor_pd(a, _mm_set1_pd(-0.0)) }
    }
    #[inline(always)]
    pub(super) fn flip(a: Repr, lo: bool, hi: bool) -> Repr {
        let sign = |x: bool| if x { -0.0 } else { 0.0 };
        unsafe { _mm_xor_pd(a, _mm_set_pd(sign(hi), sign(lo))) }
    }
    /// `x * y + c` with one rounding (the target has FMA).
    #[cfg(all(feature = "std", target_feature = "fma"))]
    #[inline(always)]
    pub(super) fn fused(x: Repr, y: Repr, c: Repr) -> Repr {
        unsafe { core::arch::x86_64::_mm_fmadd_pd(x, y, c) }
    }
}

/// [`F2`]'s lanes as two scalars.
#[cfg(not(target_arch = "x86_64"))]
mod pair {
    pub(super) type Repr = [f64; 2];

    #[inline(always)]
    pub(super) fn new(a: f64, b: f64) -> Repr {
        [a, b]
    }
    #[inline(always)]
    pub(super) fn lo(x: Repr) -> f64 {
        x[0]
    }
    #[inline(always)]
    pub(super) fn hi(x: Repr) -> f64 {
        x[1]
    }
    #[inline(always)]
    pub(super) fn add(a: Repr, b: Repr) -> Repr {
        [a[0] + b[0], a[1] + b[1]]
    }
    #[inline(always)]
    pub(super) fn sub(a: Repr, b: Repr) -> Repr {
        [a[0] - b[0], a[1] - b[1]]
    }
    #[inline(always)]
    pub(super) fn mul(a: Repr, b: Repr) -> Repr {
        [a[0] * b[0], a[1] * b[1]]
    }
    #[inline(always)]
    pub(super) fn div(a: Repr, b: Repr) -> Repr {
        [a[0] / b[0], a[1] / b[1]]
    }
    #[inline(always)]
    pub(super) fn neg(a: Repr) -> Repr {
        [-a[0], -a[1]]
    }
    #[inline(always)]
    pub(super) fn flip(a: Repr, lo: bool, hi: bool) -> Repr {
        [if lo { -a[0] } else { a[0] }, if hi { -a[1] } else { a[1] }]
    }
    /// `x * y + c` with one rounding.
    #[cfg(all(feature = "std", target_feature = "fma"))]
    #[inline(always)]
    pub(super) fn fused(x: Repr, y: Repr, c: Repr) -> Repr {
        [x[0].mul_add(y[0], c[0]), x[1].mul_add(y[1], c[1])]
    }
}

/// The same functions in `f32`, for modules generated with
/// `precision = "f32"` (which import them as `math`), the same with or
/// without `std` so that an `f32` model computes the same on a host as on a
/// microcontroller.
///
/// `sin`, `cos` and `sin_cos` are computed in `f32` arithmetic only (the
/// `libm` crate's `sincosf` evaluates in `f64`, which a Cortex-M4F emulates
/// in software at about 1,800 instructions per call): `x = k pi/2 + r` with
/// `k` the nearest integer to `2 x / pi` and `r` in `[-pi/4, pi/4]`, `pi/2`
/// split into three `f32` parts (the first two with few enough bits that
/// their products with `k` are exact for `|x| <= 6000`), then the Taylor
/// polynomials of `sin r` (to `r^9`) and `cos r` (to `r^10`), whose
/// truncation errors (below `2e-9`) are far below `f32`'s resolution, and the
/// quadrant of `k`. Larger or non-finite arguments go to `libm`'s `sincosf`.
/// Within 2 units in the last place of the exact values (tested against
/// `f64`). The others are `libm`'s single-precision routines.
pub mod f32 {
    pub use super::dispatch;

    macro_rules! unary_f32 {
        ($($(#[$doc:meta])* $name:ident => $libm:ident;)*) => {$(
            $(#[$doc])*
            #[inline(always)]
            pub fn $name(x: f32) -> f32 {
                libm::$libm(x)
            }
        )*};
    }

    unary_f32! {
        /// Tangent.
        tan => tanf;
        /// Exponential.
        exp => expf;
        /// Natural logarithm.
        ln => logf;
        /// Square root.
        sqrt => sqrtf;
        /// Absolute value.
        abs => fabsf;
    }

    switches!(f32);

    /// Largest `|x|` reduced in `f32` (see the module docs).
    const REDUCED: f32 = 6000.0;
    /// `pi/2 = PIO2_1 + PIO2_2 + PIO2_3`; `PIO2_1` has 8 significant bits,
    /// `PIO2_2` 12.
    const PIO2_1: f32 = 1.5703125;
    const PIO2_2: f32 = 4.838_705e-4;
    const PIO2_3: f32 = -4.371_139e-8;

    /// Sine and cosine of `r` in `[-pi/4, pi/4]`.
    #[inline(always)]
    fn kernel(r: f32) -> (f32, f32) {
        let z = r * r;
        let s = r + r
            * z
            * (-1.0 / 6.0 + z * (1.0 / 120.0 + z * (-1.0 / 5040.0 + z * (1.0 / 362_880.0))));
        let c = 1.0
            + z * (-0.5
                + z * (1.0 / 24.0
                    + z * (-1.0 / 720.0 + z * (1.0 / 40_320.0 + z * (-1.0 / 3_628_800.0)))));
        (s, c)
    }

    /// Sine and cosine of one argument, computed together.
    #[inline]
    pub fn sin_cos(x: f32) -> (f32, f32) {
        if !(x.abs() <= REDUCED) {
            return libm::sincosf(x);
        }
        let kf = x * core::f32::consts::FRAC_2_PI;
        let k = if kf >= 0.0 {
            (kf + 0.5) as i32
        } else {
            (kf - 0.5) as i32
        };
        let kf = k as f32;
        let r = ((x - kf * PIO2_1) - kf * PIO2_2) - kf * PIO2_3;
        let (s, c) = kernel(r);
        match k & 3 {
            0 => (s, c),
            1 => (c, -s),
            2 => (-s, -c),
            _ => (-c, s),
        }
    }

    /// Sine.
    #[inline(always)]
    pub fn sin(x: f32) -> f32 {
        sin_cos(x).0
    }

    /// Cosine.
    #[inline(always)]
    pub fn cos(x: f32) -> f32 {
        sin_cos(x).1
    }

    /// Four-quadrant arctangent of `y / x`.
    #[inline(always)]
    pub fn atan2(y: f32, x: f32) -> f32 {
        libm::atan2f(y, x)
    }

    #[cfg(test)]
    mod tests {
        use super::*;

        /// Distance in units in the last place of `f32` near `exact`.
        fn ulps(got: f32, exact: f64) -> f64 {
            let ulp = f64::from(f32::EPSILON) * exact.abs().max(f64::from(f32::MIN_POSITIVE));
            // Near zero the absolute error counts against f32's resolution at 1.
            (f64::from(got) - exact).abs() / ulp.max(f64::from(f32::EPSILON) * 2f64.powi(-8))
        }

        #[test]
        fn sin_cos_is_within_two_ulps_of_the_f64_values() {
            let mut worst = 0.0f64;
            let mut x = -REDUCED;
            while x <= REDUCED {
                for x in [x, x * 1e-3, x * 1e-6] {
                    let (s, c) = sin_cos(x);
                    let (es, ec) = libm::sincos(f64::from(x));
                    worst = worst.max(ulps(s, es)).max(ulps(c, ec));
                }
                x += 0.0137;
            }
            assert!(worst <= 2.0, "worst error {worst} ulp");
        }

        #[test]
        fn large_and_non_finite_arguments_go_to_libm() {
            for x in [1e5f32, -3e7, f32::MAX] {
                assert_eq!(sin_cos(x), libm::sincosf(x));
            }
            assert!(sin_cos(f32::NAN).0.is_nan() && sin_cos(f32::INFINITY).1.is_nan());
            assert_eq!(sin_cos(0.0), (0.0, 1.0));
        }
    }
}

/// Four-quadrant arctangent of `y / x`.
#[inline(always)]
pub fn atan2(y: f64, x: f64) -> f64 {
    #[cfg(feature = "std")]
    {
        y.atan2(x)
    }
    #[cfg(not(feature = "std"))]
    {
        libm::atan2(y, x)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Distance in units in the last place of `f64` near `reference`
    /// (near zero, against the resolution at 1).
    fn ulps(got: f64, reference: f64) -> f64 {
        (got - reference).abs() / (f64::EPSILON * reference.abs().max(f64::EPSILON))
    }

    #[test]
    fn sin_cos_is_within_one_and_a_half_ulps_of_libm() {
        let mut worst = 0.0f64;
        let mut x = -1000.0;
        while x <= 1000.0 {
            // Also near the multiples of pi/2, where the reduction cancels.
            let near =
                (x * core::f64::consts::FRAC_2_PI) as i64 as f64 * core::f64::consts::FRAC_PI_2;
            for x in [x, x * 1e-3, x * 1e-9, x * 1e3, near, near + 1e-9] {
                let (s, c) = sin_cos(x);
                let (es, ec) = libm::sincos(x);
                worst = worst.max(ulps(s, es)).max(ulps(c, ec));
            }
            x += 0.001_37;
        }
        assert!(worst <= 1.5, "worst error {worst} ulp");
    }

    #[test]
    fn large_and_non_finite_arguments_go_to_libm() {
        for x in [1.1e6, -3e9, f64::MAX] {
            assert_eq!(sin_cos(x), libm::sincos(x));
        }
        assert!(sin_cos(f64::NAN).0.is_nan() && sin_cos(f64::INFINITY).1.is_nan());
        assert_eq!(sin_cos(0.0), (0.0, 1.0));
    }

    /// Values for bitwise checks: signed zeros, extremes, infinity, NaN.
    const EDGE_VALUES: [f64; 10] = [
        0.0,
        -0.0,
        1.0,
        -2.5,
        1e-300,
        -3.7e300,
        0.1,
        7.25e-12,
        f64::INFINITY,
        f64::NAN,
    ];

    /// The same bits, or both NaN.
    fn same_bits(a: f64, b: f64) -> bool {
        a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan())
    }

    /// Every two-lane operation is, in each lane, bitwise the scalar
    /// operation the generated scalar code performs (signed zeros, NaN and
    /// infinities included).
    #[test]
    fn two_lanes_are_bitwise_the_scalar_operations() {
        let (values, same) = (EDGE_VALUES, same_bits);
        for &a in &values {
            for &b in &values {
                for &c in &values {
                    let (x, y, z) = (F2::new(a, b), F2::new(b, c), F2::new(c, a));
                    let lanes = |p: F2, lo: f64, hi: f64| same(p.lo(), lo) && same(p.hi(), hi);
                    assert!(lanes(x, a, b));
                    assert!(lanes(F2::plus(x, y), a + b, b + c));
                    assert!(lanes(F2::minus(x, y), a - b, b - c));
                    assert!(lanes(F2::times(x, y), a * b, b * c));
                    assert!(lanes(F2::over(x, y), a / b, b / c));
                    assert!(lanes(F2::negated(x), -a, -b));
                    assert!(lanes(
                        F2::mul_add(x, y, z),
                        mul_add(a, b, c),
                        mul_add(b, c, a)
                    ));
                    assert!(lanes(
                        F2::add_mul(x, y, z),
                        add_mul(a, b, c),
                        add_mul(b, c, a)
                    ));
                    assert!(lanes(
                        F2::sub_mul(x, y, z),
                        sub_mul(a, b, c),
                        sub_mul(b, c, a)
                    ));
                    assert!(lanes(
                        F2::mul_sub(x, y, z),
                        mul_sub(a, b, c),
                        mul_sub(b, c, a)
                    ));
                }
            }
        }
    }

    /// The rewrites that let two statements pair where their signs sit
    /// differently (`codegen`'s `schedule::lanes`) are exact, signed zeros,
    /// infinities and NaN included: a subtraction is the addition of the
    /// negated operand, a product's or quotient's sign moves between its
    /// operands, multiply-adds take their signs on an operand, sums and
    /// products commute; and negating one lane flips that lane only.
    #[test]
    fn sign_rewrites_of_paired_statements_are_exact() {
        let (values, same) = (EDGE_VALUES, same_bits);
        for &a in &values {
            for &b in &values {
                assert!(same(a - b, a + -b));
                assert!(same(a + b, b + a));
                assert!(same(a * b, b * a));
                assert!(same(-(a * b), -a * b) && same(a * -b, -a * b));
                assert!(same(-(a / b), -a / b) && same(a / -b, -a / b));
                let p = F2::new(a, b);
                assert!(same(F2::negated_lo(p).lo(), -a) && same(F2::negated_lo(p).hi(), b));
                assert!(same(F2::negated_hi(p).lo(), a) && same(F2::negated_hi(p).hi(), -b));
                for &c in &values {
                    assert!(same(sub_mul(c, a, b), add_mul(c, -a, b)));
                    assert!(same(mul_sub(a, b, c), add_mul(-c, a, b)));
                    assert!(same(mul_add(a, b, c), add_mul(c, a, b)));
                    assert!(same(add_mul(c, a, b), add_mul(c, b, a)));
                }
            }
        }
    }

    #[test]
    fn sin_cos_array_is_bitwise_sin_cos_lane_by_lane() {
        let bits = |(s, c): (f64, f64)| (s.to_bits(), c.to_bits());
        let x = [0.3, -2.9, 1.0e6, 7.5, f64::NAN, -0.0, 1.2e6];
        let all = sin_cos_array(x);
        let inline = sin_cos_array([x[0], x[1], x[3], x[5]]);
        for (i, &x) in x.iter().enumerate() {
            let one = sin_cos(x);
            if x.is_nan() {
                assert!(all[i].0.is_nan() && one.0.is_nan());
            } else {
                assert_eq!(bits(all[i]), bits(one), "{x}");
            }
        }
        for (sc, i) in inline.iter().zip([0, 1, 3, 5]) {
            assert_eq!(bits(*sc), bits(all[i]));
        }
        // Batches of every size take one of two paths (all lanes at once, or
        // two at a time in a loop past `ALL_AT_ONCE`): the same bits.
        let many: [f64; 21] = core::array::from_fn(|i| (i as f64 - 10.0) * 0.77 + 0.01);
        let long = sin_cos_array(many);
        let short = sin_cos_array::<3>(core::array::from_fn(|i| many[i]));
        let sixteen = sin_cos_array::<16>(core::array::from_fn(|i| many[i]));
        for (i, &x) in many.iter().enumerate() {
            assert_eq!(bits(long[i]), bits(sin_cos(x)), "{x}");
        }
        for (i, sc) in short.iter().enumerate().chain(sixteen.iter().enumerate()) {
            assert_eq!(bits(*sc), bits(long[i]));
        }
    }

    #[test]
    fn sign_and_step_take_their_documented_values_at_and_around_zero() {
        for x in [
            3.5,
            1e-300,
            -2.0,
            -1e-300,
            0.0,
            -0.0,
            f64::MAX,
            f64::INFINITY,
        ] {
            let want = if x > 0.0 {
                1.0
            } else if x < 0.0 {
                -1.0
            } else {
                0.0
            };
            assert_eq!(sign(x), want, "sign({x})");
            assert_eq!(step(x), (1.0 + want) / 2.0, "step({x})");
            assert_eq!(step(x) + step(-x), 1.0, "step({x}) + step(-{x})");
            assert_eq!(abs(x), if x < 0.0 { -x } else { x }, "abs({x})");
            let y = x as f32;
            let want = if y > 0.0 {
                1.0
            } else if y < 0.0 {
                -1.0
            } else {
                0.0
            };
            assert_eq!(f32::sign(y), want, "sign({y}f32)");
            assert_eq!(f32::step(y), (1.0 + want) / 2.0, "step({y}f32)");
            assert_eq!(f32::abs(y), if y < 0.0 { -y } else { y }, "abs({y}f32)");
        }
        assert!(sign(f64::NAN).is_nan() && step(f64::NAN).is_nan());
        assert!(f32::sign(f32::NAN).is_nan() && f32::step(f32::NAN).is_nan());
    }

    #[test]
    fn multiply_adds_compute_their_expression_rounded_once_only_where_fused() {
        // 0.1 * 10 is 1 + 2^-54 exactly: it rounds to 1, so the written
        // expressions give 0 and a fused one keeps 2^-54.
        let (x, y) = (0.1, 10.0);
        let fused = cfg!(all(feature = "std", target_feature = "fma"));
        let tail = if fused { 2f64.powi(-54) } else { 0.0 };
        assert_eq!(mul_add(x, y, -1.0), tail);
        assert_eq!(add_mul(-1.0, x, y), tail);
        assert_eq!(mul_sub(x, y, 1.0), tail);
        assert_eq!(sub_mul(1.0, x, y), -tail);
        // Ordinary values: the expression itself.
        assert_eq!(mul_add(3.0, 4.0, 5.0), 17.0);
        assert_eq!(add_mul(5.0, 3.0, 4.0), 17.0);
        assert_eq!(mul_sub(3.0, 4.0, 5.0), 7.0);
        assert_eq!(sub_mul(5.0, 3.0, 4.0), -7.0);
    }

    /// The detection agrees with the standard library's.
    #[cfg(all(target_arch = "x86_64", not(target_feature = "avx")))]
    #[test]
    fn avx_is_found_where_the_standard_library_finds_it() {
        extern crate std;
        let expected = std::is_x86_feature_detected!("avx");
        assert_eq!(avx::available(), expected);
        assert_eq!(avx::available(), expected, "cached");
    }

    /// Both copies of a dispatched body (on a processor with AVX, the AVX
    /// one runs) compute bitwise what the body computes inline: scalars,
    /// pairs, the inline sines and cosines, and written multiply-adds that
    /// stay unfused.
    #[test]
    fn dispatched_statements_compute_bitwise_what_they_compute_inline() {
        let body = |x: [f64; 6]| -> [f64; 8] {
            let [(s0, c0), (s1, c1), (s2, c2), (s3, c3)] = sin_cos_array([x[0], x[1], x[2], x[3]]);
            let p = F2::mul_add(F2::new(s0, s1), F2::new(c2, c3), F2::new(x[2], x[3]));
            let q = F2::over(p, F2::new(c0 + 2.0, c1 - 2.0));
            [
                mul_add(x[0], 10.0 / 3.0, -x[1]),
                sub_mul(s2 * c3, x[3], x[0]),
                sqrt(abs(x[2] * s3)),
                q.lo(),
                q.hi(),
                atan2(s1, c1),
                mul_add(x[4], x[5], -1.0),
                s0 * s1 - c0 * c1,
            ]
        };
        // 0.1 * 10 is 1 + 2^-54 exactly: unfused, `x[4] x[5] - 1` is 0.
        let x = core::hint::black_box([0.3, -1.7, 2.5e3, 1e-9, 0.1, 10.0]);
        let inline = body(x);
        let dispatched = dispatch(
            #[inline(always)]
            || body(x),
        );
        for (k, (a, b)) in inline.iter().zip(&dispatched).enumerate() {
            assert_eq!(a.to_bits(), b.to_bits(), "entry {k}: {a:e} vs {b:e}");
        }
        let fused = cfg!(all(feature = "std", target_feature = "fma"));
        assert_eq!(dispatched[6] == 0.0, !fused, "{:e}", dispatched[6]);
    }
}
