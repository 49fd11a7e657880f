//! Small dense factorisations over fixed (`Const`, on the stack) or
//! run-time (`Dyn`) sizes.
//!
//! Hand-written (rather than nalgebra's decompositions) so that every failure
//! is reported as a value with the numbers that show it, loops have static
//! bounds, and generic code needs no extra dimension trait bounds.

use crate::scalar::Scalar;
use nalgebra::allocator::Allocator;
use nalgebra::{DefaultAllocator, Dim, OMatrix, OVector, U1};

/// Largest absolute entry; NaN if any entry is NaN.
pub(crate) fn max_abs<T: Scalar, R: Dim, C: Dim>(a: &OMatrix<T, R, C>) -> T
where
    DefaultAllocator: Allocator<R, C>,
{
    let mut m = T::zero();
    for x in a.as_slice() {
        let ax = x.abs();
        if !(ax >= T::zero()) {
            return T::NAN;
        }
        if ax > m {
            m = ax;
        }
    }
    m
}

/// True if every entry is finite. (`x * 0` is zero for finite `x` and NaN
/// otherwise; eight independent accumulators over the contiguous storage
/// vectorise, where a short-circuiting scan over nalgebra's generic iterator
/// cost more than evaluating some of the generated terms.)
pub(crate) fn all_finite<T: Scalar, R: Dim, C: Dim>(a: &OMatrix<T, R, C>) -> bool
where
    DefaultAllocator: Allocator<R, C>,
{
    let mut acc = [T::zero(); 8];
    let mut chunks = a.as_slice().chunks_exact(8);
    for c in &mut chunks {
        for (s, x) in acc.iter_mut().zip(c) {
            *s += *x * T::zero();
        }
    }
    for (s, x) in acc.iter_mut().zip(chunks.remainder()) {
        *s += *x * T::zero();
    }
    acc.iter().all(|s| *s == T::zero())
}

/// Squared Frobenius norm (four independent accumulators).
pub(crate) fn norm_squared<T: Scalar, R: Dim, C: Dim>(a: &OMatrix<T, R, C>) -> T
where
    DefaultAllocator: Allocator<R, C>,
{
    let mut acc = [T::zero(); 4];
    let mut chunks = a.as_slice().chunks_exact(4);
    for c in &mut chunks {
        for (s, x) in acc.iter_mut().zip(c) {
            *s += *x * *x;
        }
    }
    for (s, x) in acc.iter_mut().zip(chunks.remainder()) {
        *s += *x * *x;
    }
    (acc[0] + acc[1]) + (acc[2] + acc[3])
}

/// `out += a x` for a slice `x` of length `C` and `out` of length `R`, as a
/// sum of scaled columns (contiguous, vectorisable; nalgebra's generic
/// products cost more at these sizes).
pub(crate) fn mul_vec_acc<T: Scalar, R: Dim, C: Dim>(a: &OMatrix<T, R, C>, x: &[T], out: &mut [T])
where
    DefaultAllocator: Allocator<R, C>,
{
    for (col, xk) in a.as_slice().chunks_exact(a.nrows().max(1)).zip(x) {
        for (o, e) in out.iter_mut().zip(col) {
            *o += *e * *xk;
        }
    }
}

/// `out += a b` with the zero entries of `b` skipped: each non-zero
/// `b[(k, j)]` adds `b[(k, j)]` times column `k` of `a` to column `j` of
/// `out`. For the actuator map (one non-zero per actuator in every
/// generated model: its gain on its coordinate) that is `R U`
/// multiplications where the dense product is `R Q U`. Equal to the dense
/// product up to the order of its sums (the skipped terms are zeros),
/// except that a non-finite entry of `a` against a zero of `b` gives no
/// `NaN`.
pub(crate) fn mul_sparse_acc<T: Scalar, R: Dim, Q: Dim, U: Dim>(
    a: &OMatrix<T, R, Q>,
    b: &OMatrix<T, Q, U>,
    out: &mut OMatrix<T, R, U>,
) where
    DefaultAllocator: Allocator<R, Q> + Allocator<Q, U> + Allocator<R, U>,
{
    let n = a.nrows().max(1);
    let q = b.nrows().max(1);
    for (out_col, b_col) in out
        .as_mut_slice()
        .chunks_exact_mut(n)
        .zip(b.as_slice().chunks_exact(q))
    {
        for (a_col, &bk) in a.as_slice().chunks_exact(n).zip(b_col) {
            if bk != T::zero() {
                for (o, e) in out_col.iter_mut().zip(a_col) {
                    *o += *e * bk;
                }
            }
        }
    }
}

/// `out += a^T x` for a slice `x` of length `R` and `out` of length `C`:
/// one dot product per (contiguous) column.
pub(crate) fn tr_mul_vec_acc<T: Scalar, R: Dim, C: Dim>(
    a: &OMatrix<T, R, C>,
    x: &[T],
    out: &mut [T],
) where
    DefaultAllocator: Allocator<R, C>,
{
    for (col, o) in a
        .as_slice()
        .chunks_exact(a.nrows().max(1))
        .zip(out.iter_mut())
    {
        *o += col.iter().zip(x).map(|(e, xi)| *e * *xi).sum::<T>();
    }
}

/// Index of the first non-finite entry (column-major for matrices).
pub(crate) fn first_non_finite<T: Scalar, R: Dim>(a: &OVector<T, R>) -> Option<usize>
where
    DefaultAllocator: Allocator<R>,
{
    a.as_slice().iter().position(|x| !x.is_finite())
}

/// In-place Cholesky factorisation `A = L L^T` of a symmetric matrix; only the
/// lower triangle of `a` is read, and on success it holds `L` (the strict upper
/// triangle is zeroed).
///
/// Fails with `(pivot index, pivot value)` when a pivot is not positive, or
/// is below `eps * A_jj` (numerically singular), or is not finite.
pub(crate) fn cholesky<T: Scalar, N: Dim>(a: &mut OMatrix<T, N, N>) -> Result<(), (usize, T)>
where
    DefaultAllocator: Allocator<N, N>,
{
    let n = a.nrows();
    for j in 0..n {
        let ajj = a[(j, j)];
        let mut d = ajj;
        for k in 0..j {
            d -= a[(j, k)] * a[(j, k)];
        }
        if !d.is_finite() || d <= T::EPSILON * ajj.abs() || d <= T::zero() {
            return Err((j, d));
        }
        let l = Scalar::square_root(d);
        a[(j, j)] = l;
        for i in (j + 1)..n {
            let mut s = a[(i, j)];
            for k in 0..j {
                s -= a[(i, k)] * a[(j, k)];
            }
            a[(i, j)] = s / l;
        }
        for i in 0..j {
            a[(i, j)] = T::zero();
        }
    }
    Ok(())
}

/// Solves `L x = b` in place (forward substitution) for every column of `b`.
///
/// Row by row across the columns: each column's entries are the same
/// operations in the same order as a column-by-column substitution (so the
/// same bits), while the columns' independent chains of subtractions and
/// divisions overlap in the processor (a column at a time, a solve with
/// many right-hand sides waited on each division in turn: the UR5's
/// forward-dynamics derivatives spent over a third of their time there).
pub(crate) fn solve_lower<T: Scalar, N: Dim, K: Dim>(l: &OMatrix<T, N, N>, b: &mut OMatrix<T, N, K>)
where
    DefaultAllocator: Allocator<N, N> + Allocator<N, K>,
{
    for i in 0..l.nrows() {
        for c in 0..b.ncols() {
            let mut s = b[(i, c)];
            for k in 0..i {
                s -= l[(i, k)] * b[(k, c)];
            }
            b[(i, c)] = s / l[(i, i)];
        }
    }
}

/// Solves `L^T x = b` in place (backward substitution) for every column of
/// `b`, row by row across the columns as [`solve_lower`].
pub(crate) fn solve_lower_transpose<T: Scalar, N: Dim, K: Dim>(
    l: &OMatrix<T, N, N>,
    b: &mut OMatrix<T, N, K>,
) where
    DefaultAllocator: Allocator<N, N> + Allocator<N, K>,
{
    let n = l.nrows();
    for i in (0..n).rev() {
        for c in 0..b.ncols() {
            let mut s = b[(i, c)];
            for k in (i + 1)..n {
                s -= l[(k, i)] * b[(k, c)];
            }
            b[(i, c)] = s / l[(i, i)];
        }
    }
}

/// Solves `L L^T x = b` in place for every column of `b`, `L` from
/// [`cholesky`]: [`solve_lower`], then [`solve_lower_transpose`].
pub(crate) fn solve_cholesky<T: Scalar, N: Dim, K: Dim>(
    l: &OMatrix<T, N, N>,
    b: &mut OMatrix<T, N, K>,
) where
    DefaultAllocator: Allocator<N, N> + Allocator<N, K>,
{
    solve_lower(l, b);
    solve_lower_transpose(l, b);
}

/// Symmetric positive semi-definite solver: Jacobi equilibration followed by a
/// diagonally pivoted Cholesky factorisation, which reveals (near) rank
/// deficiency through its pivots.
pub(crate) struct SpdSolver<T: Scalar, N: Dim>
where
    DefaultAllocator: Allocator<N, N> + Allocator<N>,
{
    l: OMatrix<T, N, N>,
    perm: OVector<usize, N>,
    scale: OVector<T, N>,
}

impl<T: Scalar, N: Dim> SpdSolver<T, N>
where
    DefaultAllocator: Allocator<N, N> + Allocator<N>,
{
    /// Factors `a` (symmetric, both triangles read). Returns the solver and a
    /// condition estimate of the equilibrated matrix (ratio of the largest to
    /// the smallest pivot; a lower bound of the 2-norm condition number).
    /// `Err(estimate)` when a pivot vanishes or the estimate exceeds `limit`
    /// (the estimate is `INFINITY` for an exactly singular matrix).
    pub(crate) fn factor(a: &OMatrix<T, N, N>, limit: T) -> Result<(Self, T), T> {
        let (dim, _) = a.shape_generic();
        let n = dim.value();
        let mut scale = OVector::<T, N>::zeros_generic(dim, U1);
        for i in 0..n {
            let d = a[(i, i)];
            if !(d > T::zero()) || !d.is_finite() {
                return Err(T::INFINITY);
            }
            scale[i] = T::one() / Scalar::square_root(d);
        }
        let mut w = OMatrix::<T, N, N>::zeros_generic(dim, dim);
        for j in 0..n {
            for i in 0..n {
                w[(i, j)] = scale[i] * a[(i, j)] * scale[j];
            }
        }
        let mut perm = OVector::<usize, N>::from_fn_generic(dim, U1, |i, _| i);
        let mut l = OMatrix::<T, N, N>::zeros_generic(dim, dim);
        let mut dmax = T::zero();
        let mut dmin = T::INFINITY;
        for j in 0..n {
            // Choose the largest remaining diagonal.
            let mut p = j;
            for i in (j + 1)..n {
                if w[(i, i)] > w[(p, p)] {
                    p = i;
                }
            }
            if p != j {
                w.swap_rows(j, p);
                w.swap_columns(j, p);
                l.swap_rows(j, p);
                perm.swap_rows(j, p);
            }
            let d = w[(j, j)];
            if j == 0 {
                dmax = d;
            }
            if !(d > T::zero()) || !d.is_finite() || d <= T::of(4.0) * T::EPSILON * dmax {
                return Err(T::INFINITY);
            }
            dmin = dmin.min(d);
            let ljj = Scalar::square_root(d);
            l[(j, j)] = ljj;
            for i in (j + 1)..n {
                l[(i, j)] = w[(i, j)] / ljj;
            }
            for k in (j + 1)..n {
                for i in (j + 1)..n {
                    w[(i, k)] -= l[(i, j)] * l[(k, j)];
                }
            }
        }
        let estimate = if n == 0 { T::one() } else { dmax / dmin };
        if !(estimate <= limit) {
            return Err(estimate);
        }
        Ok((SpdSolver { l, perm, scale }, estimate))
    }

    /// Solves `A x = b` in place.
    pub(crate) fn solve(&self, b: &mut OVector<T, N>) {
        // (D A D) y = D b, x = D y, with P (D A D) P^T = L L^T.
        let n = b.nrows();
        let mut y = OVector::<T, N>::zeros_generic(b.shape_generic().0, U1);
        for i in 0..n {
            let pi = self.perm[i];
            y[i] = self.scale[pi] * b[pi];
        }
        solve_cholesky(&self.l, &mut y);
        for i in 0..n {
            let pi = self.perm[i];
            b[pi] = self.scale[pi] * y[i];
        }
    }
}

/// LU factorisation with partial pivoting, `P A = L U`.
pub(crate) struct Lu<T: Scalar, N: Dim>
where
    DefaultAllocator: Allocator<N, N> + Allocator<N>,
{
    lu: OMatrix<T, N, N>,
    perm: OVector<usize, N>,
}

impl<T: Scalar, N: Dim> Lu<T, N>
where
    DefaultAllocator: Allocator<N, N> + Allocator<N>,
{
    /// Factors `a`. Returns the factorisation and a condition estimate
    /// (largest entry of `A` over the smallest pivot magnitude); `Err(estimate)`
    /// when a pivot is zero / not finite or the estimate exceeds `limit`.
    pub(crate) fn factor(a: &OMatrix<T, N, N>, limit: T) -> Result<(Self, T), T> {
        let norm = max_abs(a);
        if !norm.is_finite() {
            return Err(T::INFINITY);
        }
        let (dim, _) = a.shape_generic();
        let n = dim.value();
        let mut lu = a.clone();
        let mut perm = OVector::<usize, N>::from_fn_generic(dim, U1, |i, _| i);
        let mut pmin = T::INFINITY;
        for j in 0..n {
            let mut p = j;
            for i in (j + 1)..n {
                if lu[(i, j)].abs() > lu[(p, j)].abs() {
                    p = i;
                }
            }
            if p != j {
                lu.swap_rows(j, p);
                perm.swap_rows(j, p);
            }
            let piv = lu[(j, j)];
            if piv == T::zero() || !piv.is_finite() {
                return Err(T::INFINITY);
            }
            pmin = pmin.min(piv.abs());
            for i in (j + 1)..n {
                let f = lu[(i, j)] / piv;
                lu[(i, j)] = f;
                for k in (j + 1)..n {
                    let x = lu[(j, k)];
                    lu[(i, k)] -= f * x;
                }
            }
        }
        let estimate = if n == 0 { T::one() } else { norm / pmin };
        if !(estimate <= limit) {
            return Err(estimate);
        }
        Ok((Lu { lu, perm }, estimate))
    }

    /// Solves `A x = b` in place.
    pub(crate) fn solve(&self, b: &mut OVector<T, N>) {
        let n = b.nrows();
        let mut y = OVector::<T, N>::zeros_generic(b.shape_generic().0, U1);
        for i in 0..n {
            y[i] = b[self.perm[i]];
        }
        for i in 0..n {
            let mut s = y[i];
            for k in 0..i {
                s -= self.lu[(i, k)] * y[k];
            }
            y[i] = s;
        }
        for i in (0..n).rev() {
            let mut s = y[i];
            for k in (i + 1)..n {
                s -= self.lu[(i, k)] * y[k];
            }
            y[i] = s / self.lu[(i, i)];
        }
        *b = y;
    }
}

/// Inverts a square matrix in place. Returns `false` (leaving `m`
/// unspecified) when it is singular: a zero or non-finite pivot, or an
/// inverse with a non-finite entry. The caller judges the conditioning, e.g.
/// from `|A|_F |A^-1|_F`, an upper bound of the 2-norm condition number.
///
/// A matrix that splits into independent diagonal blocks of at most 3 x 3
/// after permuting rows and columns ([`SmallBlocks`]; e.g. the
/// free-coordinate Jacobian of a parallel robot, one block per chain, or a
/// 3 x 3 matrix) is inverted block by block in closed form, adjugate over
/// determinant. Elimination is one long chain of dependent divisions and
/// updates; the closed-form blocks are short independent chains that the
/// processor overlaps (with the slice kernels of this module, the rigid
/// robot's inverse-dynamics call went from 1.78 to 1.60 us). Anything
/// else, and a block whose determinant is zero or not finite (e.g. by
/// underflow), goes to [`gauss_jordan`].
pub(crate) fn invert_in_place<T: Scalar, N: Dim>(m: &mut OMatrix<T, N, N>) -> bool
where
    DefaultAllocator: Allocator<N, N> + Allocator<N>,
{
    if let Some(blocks) = SmallBlocks::of(m) {
        let a = m.clone();
        if blocks.invert(&a, m) {
            return true;
        }
        *m = a;
    }
    gauss_jordan(m)
}

/// The partition of a square matrix (up to 64 x 64) into independent
/// diagonal blocks after permuting rows and columns: the connected
/// components of its non-zero pattern (a NaN counts as non-zero). Exists
/// only when every block is square and at most 3 x 3.
struct SmallBlocks<N: Dim>
where
    DefaultAllocator: Allocator<N>,
{
    /// Row and column sets of each block, as bit masks.
    blocks: OVector<(u64, u64), N>,
    count: usize,
}

impl<N: Dim> SmallBlocks<N>
where
    DefaultAllocator: Allocator<N>,
{
    fn of<T: Scalar>(a: &OMatrix<T, N, N>) -> Option<Self>
    where
        DefaultAllocator: Allocator<N, N>,
    {
        let (dim, _) = a.shape_generic();
        let n = dim.value();
        let mut blocks = OVector::<(u64, u64), N>::from_element_generic(dim, U1, (0, 0));
        if n <= 3 {
            // One block, whatever the pattern (the closed form is general).
            if n > 0 {
                blocks[0] = ((1 << n) - 1, (1 << n) - 1);
            }
            return Some(SmallBlocks {
                blocks,
                count: n.min(1),
            });
        }
        if n > 64 {
            return None;
        }
        let mut count = 0;
        // Add the columns one by one: column j joins (and merges) every
        // block that shares a non-zero row with it.
        for (j, col) in a.as_slice().chunks_exact(n).enumerate() {
            let mut rows = 0u64;
            for (i, x) in col.iter().enumerate() {
                rows |= u64::from(*x != T::zero()) << i;
            }
            let mut cols = 1u64 << j;
            let mut k = 0;
            while k < count {
                if blocks[k].0 & rows != 0 {
                    rows |= blocks[k].0;
                    cols |= blocks[k].1;
                    count -= 1;
                    blocks[k] = blocks[count];
                } else {
                    k += 1;
                }
            }
            blocks[count] = (rows, cols);
            count += 1;
        }
        for &(rows, cols) in &blocks.as_slice()[..count] {
            let size = cols.count_ones();
            if size > 3 || rows.count_ones() != size {
                return None;
            }
        }
        Some(SmallBlocks { blocks, count })
    }

    /// Writes the inverse of `a` to `inv`; `false` when a block's
    /// determinant is zero or not finite, or the inverse is not finite.
    fn invert<T: Scalar>(&self, a: &OMatrix<T, N, N>, inv: &mut OMatrix<T, N, N>) -> bool
    where
        DefaultAllocator: Allocator<N, N>,
    {
        // (Through the slice: nalgebra's `fill` is an element-wise loop.)
        inv.as_mut_slice().fill(T::zero());
        for &(rows, cols) in &self.blocks.as_slice()[..self.count] {
            let (mut r, mut c) = ([0usize; 3], [0usize; 3]);
            let size = bit_indices(rows, &mut r);
            bit_indices(cols, &mut c);
            // The inverse's block sits at the transposed place: (c, r).
            let b = |i: usize, j: usize| a[(r[i], c[j])];
            let ok = match size {
                1 => {
                    inv[(c[0], r[0])] = T::one() / b(0, 0);
                    true
                }
                2 => {
                    let det = b(0, 0) * b(1, 1) - b(0, 1) * b(1, 0);
                    let s = T::one() / det;
                    inv[(c[0], r[0])] = b(1, 1) * s;
                    inv[(c[0], r[1])] = -b(0, 1) * s;
                    inv[(c[1], r[0])] = -b(1, 0) * s;
                    inv[(c[1], r[1])] = b(0, 0) * s;
                    det != T::zero() && s.is_finite()
                }
                _ => {
                    // Cofactors of the first row, the determinant, then the
                    // adjugate (transposed cofactors) over it.
                    let c00 = b(1, 1) * b(2, 2) - b(1, 2) * b(2, 1);
                    let c01 = b(1, 2) * b(2, 0) - b(1, 0) * b(2, 2);
                    let c02 = b(1, 0) * b(2, 1) - b(1, 1) * b(2, 0);
                    let det = b(0, 0) * c00 + b(0, 1) * c01 + b(0, 2) * c02;
                    let s = T::one() / det;
                    inv[(c[0], r[0])] = c00 * s;
                    inv[(c[1], r[0])] = c01 * s;
                    inv[(c[2], r[0])] = c02 * s;
                    inv[(c[0], r[1])] = (b(0, 2) * b(2, 1) - b(0, 1) * b(2, 2)) * s;
                    inv[(c[1], r[1])] = (b(0, 0) * b(2, 2) - b(0, 2) * b(2, 0)) * s;
                    inv[(c[2], r[1])] = (b(0, 1) * b(2, 0) - b(0, 0) * b(2, 1)) * s;
                    inv[(c[0], r[2])] = (b(0, 1) * b(1, 2) - b(0, 2) * b(1, 1)) * s;
                    inv[(c[1], r[2])] = (b(0, 2) * b(1, 0) - b(0, 0) * b(1, 2)) * s;
                    inv[(c[2], r[2])] = (b(0, 0) * b(1, 1) - b(0, 1) * b(1, 0)) * s;
                    det != T::zero() && s.is_finite()
                }
            };
            if !ok {
                return false;
            }
        }
        all_finite(inv)
    }
}

/// Writes the indices of the set bits of `mask` (at most 3) to `out` and
/// returns how many there are.
fn bit_indices(mut mask: u64, out: &mut [usize; 3]) -> usize {
    let mut n = 0;
    while mask != 0 && n < 3 {
        out[n] = mask.trailing_zeros() as usize;
        mask &= mask - 1;
        n += 1;
    }
    n
}

/// Inverts a square matrix in place by Gauss–Jordan elimination with
/// partial (row) pivoting: the pivot sequence of LU with partial pivoting,
/// at most `N^3` multiply-adds in column-oriented (vectorisable) updates.
/// Columns whose pivot-row entry is zero are skipped, and when few
/// multipliers are non-zero only their rows are updated, so sparse matrices
/// cost less, with results identical to the dense elimination. Returns
/// `false` (leaving `m` unspecified) when a pivot is zero or not finite, or
/// the inverse has a non-finite entry.
fn gauss_jordan<T: Scalar, N: Dim>(m: &mut OMatrix<T, N, N>) -> bool
where
    DefaultAllocator: Allocator<N, N> + Allocator<N>,
{
    let (dim, _) = m.shape_generic();
    let n = dim.value();
    let mut pivots = OVector::<usize, N>::from_element_generic(dim, U1, 0);
    // Multipliers (column k without the pivot row) and the rows where they
    // are non-zero.
    let mut f = OVector::<T, N>::zeros_generic(dim, U1);
    let mut rows = OVector::<usize, N>::from_element_generic(dim, U1, 0);
    for k in 0..n {
        let mut p = k;
        let mut best = m[(k, k)].abs();
        for i in (k + 1)..n {
            let v = m[(i, k)].abs();
            if v > best {
                best = v;
                p = i;
            }
        }
        if !(best > T::zero()) || !best.is_finite() {
            return false;
        }
        pivots[k] = p;
        if p != k {
            m.swap_rows(k, p);
        }
        let inv_pivot = T::one() / m[(k, k)];
        // Column k becomes the k-th unit vector, which the elimination turns
        // into the k-th column of the inverse in progress.
        let mut n_rows = 0;
        for (i, fi) in f.iter_mut().enumerate() {
            let x = m[(i, k)];
            *fi = T::zero();
            if i != k && x != T::zero() {
                *fi = x;
                rows[n_rows] = i;
                n_rows += 1;
            }
        }
        m.column_mut(k).fill(T::zero());
        m[(k, k)] = T::one();
        let sparse = 4 * n_rows <= n;
        for col in m.as_mut_slice().chunks_exact_mut(n) {
            let ck = col[k];
            if ck != T::zero() {
                let c = ck * inv_pivot;
                if sparse {
                    for &i in &rows.as_slice()[..n_rows] {
                        col[i] -= f[i] * c;
                    }
                } else {
                    for (x, fi) in col.iter_mut().zip(f.iter()) {
                        *x -= *fi * c;
                    }
                }
                col[k] = c;
            }
        }
    }
    // The loop inverted P A; A^-1 = (P A)^-1 P undoes the row swaps as
    // column swaps in reverse order.
    for k in (0..n).rev() {
        if pivots[k] != k {
            m.swap_columns(k, pivots[k]);
        }
    }
    all_finite(m)
}

/// Thin singular value decomposition `A = U S V^T` of an `R x C` matrix by
/// one-sided (Hestenes) Jacobi rotations. Works for any shape; when `C > R`
/// at least `C - R` singular values are zero.
pub(crate) struct Svd<T: Scalar, R: Dim, C: Dim>
where
    DefaultAllocator: Allocator<R, C> + Allocator<C, C> + Allocator<C>,
{
    /// Columns `sigma_j u_j` (i.e. `A V`).
    us: OMatrix<T, R, C>,
    /// Right singular vectors as columns.
    v: OMatrix<T, C, C>,
    /// Singular values (unsorted, aligned with the columns).
    sigma: OVector<T, C>,
    /// Indices of `sigma` in decreasing order.
    order: OVector<usize, C>,
}

impl<T: Scalar, R: Dim, C: Dim> Svd<T, R, C>
where
    DefaultAllocator: Allocator<R, C> + Allocator<C, C> + Allocator<C> + Allocator<R>,
{
    /// Decomposes `a`; `Err(sweeps)` if the rotations have not converged
    /// (all column pairs orthogonal to working precision) within `max_sweeps`.
    /// `a` must be finite.
    pub(crate) fn new(a: &OMatrix<T, R, C>, max_sweeps: u32) -> Result<Self, u32> {
        let (rows, cols) = a.shape_generic();
        let (r, c) = (rows.value(), cols.value());
        let mut w = a.clone();
        let mut v = OMatrix::<T, C, C>::identity_generic(cols, cols);
        // Columns below `eps |A|_F` are numerically zero (their singular
        // values are below it): rotating them against the others only
        // shuffles rounding errors and never meets the orthogonality test, so
        // pairs with such a column are skipped (exactly dependent columns,
        // e.g. repeated constraints, would otherwise never converge).
        let negligible = {
            let e = T::EPSILON * a.norm();
            e * e
        };
        let mut converged = c < 2;
        let mut sweep = 0;
        while !converged && sweep < max_sweeps {
            sweep += 1;
            let mut rotated = false;
            for p in 0..c {
                for q in (p + 1)..c {
                    let mut alpha = T::zero();
                    let mut beta = T::zero();
                    let mut gamma = T::zero();
                    for i in 0..r {
                        alpha += w[(i, p)] * w[(i, p)];
                        beta += w[(i, q)] * w[(i, q)];
                        gamma += w[(i, p)] * w[(i, q)];
                    }
                    if gamma == T::zero()
                        || gamma.abs()
                            <= T::EPSILON * Scalar::square_root(alpha) * Scalar::square_root(beta)
                        || alpha <= negligible
                        || beta <= negligible
                    {
                        continue;
                    }
                    rotated = true;
                    let zeta = (beta - alpha) / (T::of(2.0) * gamma);
                    let t = if zeta.abs() > T::of(1e100) {
                        T::of(0.5) / zeta
                    } else {
                        let sgn = if zeta >= T::zero() {
                            T::one()
                        } else {
                            -T::one()
                        };
                        sgn / (zeta.abs() + Scalar::square_root(T::one() + zeta * zeta))
                    };
                    let cs = T::one() / Scalar::square_root(T::one() + t * t);
                    let sn = cs * t;
                    for i in 0..r {
                        let wp = w[(i, p)];
                        let wq = w[(i, q)];
                        w[(i, p)] = cs * wp - sn * wq;
                        w[(i, q)] = sn * wp + cs * wq;
                    }
                    for i in 0..c {
                        let vp = v[(i, p)];
                        let vq = v[(i, q)];
                        v[(i, p)] = cs * vp - sn * vq;
                        v[(i, q)] = sn * vp + cs * vq;
                    }
                }
            }
            if !rotated {
                converged = true;
            }
        }
        if !converged {
            return Err(sweep);
        }
        let mut sigma = OVector::<T, C>::zeros_generic(cols, U1);
        for j in 0..c {
            sigma[j] = w.column(j).norm();
        }
        let mut order = OVector::<usize, C>::from_fn_generic(cols, U1, |i, _| i);
        // Insertion sort, decreasing.
        for i in 1..c {
            let mut k = i;
            while k > 0 && sigma[order[k - 1]] < sigma[order[k]] {
                order.swap_rows(k - 1, k);
                k -= 1;
            }
        }
        Ok(Svd {
            us: w,
            v,
            sigma,
            order,
        })
    }

    /// Largest singular value (0 for an empty matrix).
    pub(crate) fn sigma_max(&self) -> T {
        if self.order.is_empty() {
            T::zero()
        } else {
            self.sigma[self.order[0]]
        }
    }

    /// The `k`-th largest singular value (0-based); 0 if out of range.
    pub(crate) fn sigma_sorted(&self, k: usize) -> T {
        if k < self.order.len() {
            self.sigma[self.order[k]]
        } else {
            T::zero()
        }
    }

    /// Number of singular values above `rel_tol * sigma_max`.
    pub(crate) fn rank(&self, rel_tol: T) -> usize {
        let thr = rel_tol * self.sigma_max();
        let mut r = 0;
        for k in 0..self.order.len() {
            if self.sigma[self.order[k]] > thr && self.sigma[self.order[k]] > T::zero() {
                r += 1;
            }
        }
        r
    }

    /// Condition of the leading `k` singular values, `sigma_1 / sigma_k`
    /// (`INFINITY` if `sigma_k` is zero, 1 for `k == 0`).
    pub(crate) fn condition_of_leading(&self, k: usize) -> T {
        if k == 0 {
            return T::one();
        }
        let sk = self.sigma_sorted(k - 1);
        if sk > T::zero() {
            self.sigma_max() / sk
        } else {
            T::INFINITY
        }
    }

    /// Least-squares minimum-norm solution of `A x = b` using the leading
    /// `rank` singular triplets.
    pub(crate) fn solve(&self, b: &OVector<T, R>, rank: usize, x: &mut OVector<T, C>) {
        x.fill(T::zero());
        for k in 0..rank.min(self.order.len()) {
            let j = self.order[k];
            let s2 = self.sigma[j] * self.sigma[j];
            if s2 > T::zero() {
                let coef = self.us.column(j).dot(b) / s2;
                *x += self.v.column(j) * coef;
            }
        }
    }

    /// Least-squares minimum-norm solution of `A^T y = c` using the leading
    /// `rank` singular triplets.
    pub(crate) fn solve_transpose(&self, c: &OVector<T, C>, rank: usize, y: &mut OVector<T, R>) {
        y.fill(T::zero());
        for k in 0..rank.min(self.order.len()) {
            let j = self.order[k];
            let s2 = self.sigma[j] * self.sigma[j];
            if s2 > T::zero() {
                let coef = self.v.column(j).dot(c) / s2;
                *y += self.us.column(j) * coef;
            }
        }
    }

    /// Removes from `x` its component in the span of the leading `rank` left
    /// singular vectors (i.e. projects onto the orthogonal complement of the
    /// range of `A`).
    pub(crate) fn remove_range(&self, x: &mut OVector<T, R>, rank: usize) {
        for k in 0..rank.min(self.order.len()) {
            let j = self.order[k];
            let s2 = self.sigma[j] * self.sigma[j];
            if s2 > T::zero() {
                let coef = self.us.column(j).dot(x) / s2;
                *x -= self.us.column(j) * coef;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{SMatrix, SVector};

    #[test]
    fn cholesky_solves() {
        let a = SMatrix::<f64, 3, 3>::new(4.0, 2.0, 0.4, 2.0, 3.0, 0.5, 0.4, 0.5, 2.0);
        let mut l = a;
        assert!(cholesky(&mut l).is_ok());
        let b = SVector::<f64, 3>::new(1.0, -2.0, 0.5);
        let mut x = SMatrix::<f64, 3, 1>::from_column_slice(b.as_slice());
        solve_lower(&l, &mut x);
        solve_lower_transpose(&l, &mut x);
        assert!((a * x - b).norm() < 1e-14);
        let mut bad = SMatrix::<f64, 2, 2>::new(1.0, 2.0, 2.0, 1.0);
        assert!(matches!(cholesky(&mut bad), Err((1, _))));
    }

    #[test]
    fn solves_of_many_columns_equal_their_columns_solved_alone() {
        let a = SMatrix::<f64, 4, 4>::from_fn(|i, j| {
            let (x, y) = (i as f64, j as f64);
            (1.0 + x + y).recip() + if i == j { 1.5 } else { 0.0 }
        });
        let mut l = a;
        assert!(cholesky(&mut l).is_ok());
        let b = SMatrix::<f64, 4, 5>::from_fn(|i, j| (0.3 + 1.7 * i as f64 - 0.9 * j as f64).sin());
        let mut x = b;
        solve_cholesky(&l, &mut x);
        for j in 0..5 {
            let mut alone = b.fixed_columns::<1>(j).into_owned();
            solve_cholesky(&l, &mut alone);
            assert_eq!(x.column(j), alone.column(0), "column {j}");
            assert!((a * alone - b.column(j)).norm() < 1e-14);
        }
    }

    /// The product skipping `b`'s zeros adds the dense one, at fixed and
    /// run-time sizes (an actuator map with one gain per column, a map with
    /// two actuators on one coordinate and an empty column, empty sizes).
    #[test]
    fn products_skipping_zeros_equal_the_dense_products() {
        let a = SMatrix::<f64, 4, 3>::from_fn(|i, j| (0.4 + 1.3 * i as f64 - 0.7 * j as f64).cos());
        let b = SMatrix::<f64, 3, 4>::from_row_slice(&[
            2.0, 0.0, 0.0, -0.5, 0.0, 0.0, 1.5, 0.0, 0.0, 0.0, 0.0, 3.0,
        ]);
        let product = |a, b| {
            let mut out = SMatrix::<f64, 4, 4>::zeros();
            mul_sparse_acc(a, b, &mut out);
            out
        };
        let got = product(&a, &b);
        assert!((got - a * b).abs().max() <= 1e-15, "{got} vs {}", a * b);
        #[cfg(feature = "alloc")]
        {
            let dyn_a = nalgebra::DMatrix::from_column_slice(4, 3, a.as_slice());
            let dyn_b = nalgebra::DMatrix::from_column_slice(3, 4, b.as_slice());
            let mut out = nalgebra::DMatrix::zeros(4, 4);
            mul_sparse_acc(&dyn_a, &dyn_b, &mut out);
            assert_eq!(out.as_slice(), got.as_slice());
            let empty = nalgebra::DMatrix::<f64>::zeros(4, 0);
            let none = nalgebra::DMatrix::<f64>::zeros(0, 2);
            let mut out = nalgebra::DMatrix::from_element(4, 2, 1.0);
            mul_sparse_acc(&empty, &none, &mut out);
            assert_eq!(out, nalgebra::DMatrix::from_element(4, 2, 1.0));
        }
        let mut out = SMatrix::<f64, 4, 2>::from_element(1.0);
        mul_sparse_acc(
            &SMatrix::<f64, 4, 0>::zeros(),
            &SMatrix::<f64, 0, 2>::zeros(),
            &mut out,
        );
        assert_eq!(out, SMatrix::<f64, 4, 2>::from_element(1.0));
    }

    #[test]
    fn spd_and_lu_solve_and_detect_singular() {
        let a = SMatrix::<f64, 3, 3>::new(4.0, 2.0, 0.4, 2.0, 3.0, 0.5, 0.4, 0.5, 2.0);
        let b = SVector::<f64, 3>::new(1.0, -2.0, 0.5);
        let (s, _) = SpdSolver::factor(&a, 1e12)
            .ok()
            .unwrap_or_else(|| unreachable!());
        let mut x = b;
        s.solve(&mut x);
        assert!((a * x - b).norm() < 1e-14);
        let (lu, _) = Lu::factor(&a, 1e12).ok().unwrap_or_else(|| unreachable!());
        let mut y = b;
        lu.solve(&mut y);
        assert!((a * y - b).norm() < 1e-14);
        let sing = SMatrix::<f64, 2, 2>::new(1.0, 2.0, 2.0, 4.0);
        assert!(SpdSolver::factor(&sing, 1e12).is_err());
        assert!(Lu::factor(&sing, 1e12).is_err());
    }

    #[test]
    fn gauss_jordan_inverse() {
        let a = SMatrix::<f64, 4, 4>::new(
            0.0, 2.0, 0.4, 1.0, 2.0, 3.0, 0.5, -1.0, 0.4, 0.5, 2.0, 0.0, 1.0, 0.0, -3.0, 0.2,
        );
        let mut inv = a;
        assert!(invert_in_place(&mut inv));
        assert!((a * inv - SMatrix::<f64, 4, 4>::identity()).amax() < 1e-14);
        assert!((inv * a - SMatrix::<f64, 4, 4>::identity()).amax() < 1e-14);
        // Block diagonal (after a permutation): zero columns are skipped.
        let b = SMatrix::<f64, 4, 4>::new(
            0.0, 2.0, 0.0, 0.0, 3.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.5, -1.0, 0.0, 0.0, 0.5, 2.0,
        );
        let mut binv = b;
        assert!(invert_in_place(&mut binv));
        assert!((b * binv - SMatrix::<f64, 4, 4>::identity()).amax() < 1e-15);
        assert_eq!(binv[(0, 2)], 0.0);
        let mut sing = SMatrix::<f64, 2, 2>::new(1.0, 2.0, 2.0, 4.0);
        assert!(!invert_in_place(&mut sing));
        assert!(!invert_in_place(&mut SMatrix::<f64, 2, 2>::new(
            f64::NAN,
            0.0,
            0.0,
            1.0
        )));
        assert!(!invert_in_place(&mut SMatrix::<f64, 2, 2>::new(
            1.0,
            0.0,
            0.0,
            f64::INFINITY
        )));
        assert!(invert_in_place(&mut SMatrix::<f64, 0, 0>::zeros()));
        assert!(all_finite(&SMatrix::<f64, 3, 5>::from_element(1e308)));
        let mut x = SMatrix::<f64, 3, 5>::from_element(1.0);
        for v in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
            x[(2, 4)] = v;
            assert!(!all_finite(&x));
        }
        assert_eq!(norm_squared(&SMatrix::<f64, 3, 5>::identity()), 3.0);
        assert_eq!(norm_squared(&b), 4.0 + 9.0 + 1.0 + 2.25 + 1.0 + 0.25 + 4.0);
    }

    /// Deterministic pseudo-random numbers in [-1, 1) (a fixed-seed LCG).
    fn uniform(state: &mut u64) -> f64 {
        *state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (*state >> 11) as f64 / (1u64 << 52) as f64 - 1.0
    }

    /// The closed-form block inverse against nalgebra's LU inverse (an
    /// independent implementation) and against elimination, on random
    /// matrices with 1 x 1, 2 x 2 and 3 x 3 blocks hidden by row and column
    /// permutations, on dense 3 x 3 and 2 x 2 matrices, and on a dense 6 x 6
    /// that must take elimination.
    #[test]
    fn block_inverse_matches_lu() {
        let mut state = 7u64;
        for trial in 0..200 {
            // Blocks {0,1,2}, {3,4}, {5}, {6,7,8} before permuting.
            let mut a = SMatrix::<f64, 9, 9>::zeros();
            for (start, size) in [(0, 3), (3, 2), (5, 1), (6, 3)] {
                for i in start..start + size {
                    for j in start..start + size {
                        a[(i, j)] = uniform(&mut state) + if i == j { 2.0 } else { 0.0 };
                    }
                }
            }
            let (mut rows, mut cols) = ([0usize; 9], [0usize; 9]);
            for (k, (r, c)) in rows.iter_mut().zip(cols.iter_mut()).enumerate() {
                (*r, *c) = (k, k);
            }
            for k in (1..9).rev() {
                let i = ((uniform(&mut state) + 1.0) * 0.5 * (k + 1) as f64) as usize;
                rows.swap(k, i.min(k));
                let j = ((uniform(&mut state) + 1.0) * 0.5 * (k + 1) as f64) as usize;
                cols.swap(k, j.min(k));
            }
            let p = SMatrix::<f64, 9, 9>::from_fn(|i, j| a[(rows[i], cols[j])]);
            assert!(SmallBlocks::of(&p).is_some(), "trial {trial}: blocks found");
            let mut inv = p;
            assert!(invert_in_place(&mut inv));
            let lu = p.try_inverse().unwrap_or_else(|| unreachable!());
            let mut gj = p;
            assert!(gauss_jordan(&mut gj));
            let scale = lu.amax();
            assert!((inv - lu).amax() <= 1e-13 * scale, "trial {trial}");
            assert!((inv - gj).amax() <= 1e-13 * scale, "trial {trial}");
            // Zero outside the (transposed) blocks, exactly.
            for i in 0..9 {
                for j in 0..9 {
                    if p[(j, i)] == 0.0 && lu[(i, j)].abs() < 1e-300 {
                        assert_eq!(inv[(i, j)], 0.0);
                    }
                }
            }
            let d3 = SMatrix::<f64, 3, 3>::from_fn(|_, _| uniform(&mut state));
            let mut inv3 = d3;
            if let Some(lu3) = d3.try_inverse() {
                assert!(invert_in_place(&mut inv3));
                let cond = d3.norm() * lu3.norm();
                assert!(
                    (inv3 - lu3).amax() <= 1e-15 * cond * lu3.amax(),
                    "trial {trial}"
                );
            }
            let d2 = SMatrix::<f64, 2, 2>::from_fn(|_, _| uniform(&mut state));
            let mut inv2 = d2;
            let lu2 = d2.try_inverse().unwrap_or_else(|| unreachable!());
            assert!(invert_in_place(&mut inv2));
            assert!((inv2 - lu2).amax() <= 1e-15 * d2.norm() * lu2.norm() * lu2.amax());
        }
        // Dense 6 x 6: no small blocks, elimination.
        let d6 = SMatrix::<f64, 6, 6>::from_fn(|i, j| {
            uniform(&mut state) + if i == j { 3.0 } else { 0.0 }
        });
        assert!(SmallBlocks::of(&d6).is_none());
        let mut inv6 = d6;
        assert!(invert_in_place(&mut inv6));
        assert!((d6 * inv6 - SMatrix::<f64, 6, 6>::identity()).amax() < 1e-14);
    }

    /// A block whose determinant underflows (entries 1e-110, determinant
    /// 1e-330) falls back to elimination, which inverts it; singular and
    /// non-finite blocks are refused.
    #[test]
    fn block_inverse_fallbacks() {
        let a = SMatrix::<f64, 3, 3>::new(2.0, 1.0, 0.0, 1.0, 3.0, 1.0, 0.0, 1.0, 4.0) * 1e-110;
        let mut inv = a;
        assert!(invert_in_place(&mut inv));
        assert!((a * inv - SMatrix::<f64, 3, 3>::identity()).amax() < 1e-15);
        let mut b = SMatrix::<f64, 4, 4>::identity();
        b[(1, 1)] = 0.0;
        assert!(!invert_in_place(&mut b));
        let mut c = SMatrix::<f64, 3, 3>::new(1.0, 2.0, 3.0, 2.0, 4.0, 6.0, 0.0, 1.0, 1.0);
        assert!(!invert_in_place(&mut c));
        let mut d = SMatrix::<f64, 4, 4>::identity();
        d[(2, 3)] = f64::NAN;
        assert!(!invert_in_place(&mut d));
    }

    #[test]
    fn svd_min_norm() {
        // Underdetermined 2x3 system via A^T (3x2).
        let a = SMatrix::<f64, 2, 3>::new(1.0, 2.0, 3.0, 0.0, 1.0, -1.0);
        let at = a.transpose();
        let svd = Svd::new(&at, 30).ok().unwrap_or_else(|| unreachable!());
        assert_eq!(svd.rank(1e-12), 2);
        let c = SVector::<f64, 2>::new(1.0, 2.0);
        let mut x = SVector::<f64, 3>::zeros();
        svd.solve_transpose(&c, 2, &mut x);
        assert!((a * x - c).norm() < 1e-14);
        // Minimum norm: x lies in the row space of A.
        let n = a.row(0).transpose().cross(&a.row(1).transpose());
        assert!(x.dot(&n).abs() < 1e-14);
    }
}
