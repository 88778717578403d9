//! The matrix product behind every layer, on the `gemm` crate (blocked, runtime-dispatched SIMD
//! kernels; the one candle uses), with bounds checked once here so that no other module touches
//! raw pointers. `matrixmultiply` was measured too: about 10 % slower on these shapes.

use std::fmt::Debug;
use std::iter::Sum;

/// A floating-point type the kernel computes in.
pub trait Real:
    num_traits::Float + Sum + Default + Debug + Send + Sync + std::ops::AddAssign + 'static
{
    fn of(x: f64) -> Self;

    /// ELU (alpha 1) of every element, in place.
    fn elu_in_place(xs: &mut [Self]);
}

impl Real for f32 {
    fn of(x: f64) -> Self {
        x as f32
    }

    fn elu_in_place(xs: &mut [f32]) {
        // Branch-free, so that the loop vectorises; glibc's expm1f took a quarter of the update.
        for x in xs {
            let e = exp_nonpositive(x.min(0.0)) - 1.0;
            *x = if *x > 0.0 { *x } else { e };
        }
    }
}

/// `exp(x)` for `x <= 0` in f32, to about 1 ulp: Cephes' `expf` (range reduction by ln 2 and
/// its degree-6 polynomial; constants from the Cephes library's `expf.c`, public domain).
#[inline]
fn exp_nonpositive(x: f32) -> f32 {
    const LOG2E: f32 = std::f32::consts::LOG2_E;
    const C1: f32 = 0.693_359_4;
    const C2: f32 = -2.121_944_4e-4;
    // Round to nearest by adding and subtracting 1.5 * 2^23 (no call to floorf, so the loop
    // vectorises on baseline x86-64).
    const ROUND: f32 = 12_582_912.0;
    let x = x.max(-87.0);
    let n = (x * LOG2E + ROUND) - ROUND;
    let r = x - n * C1 - n * C2;
    let p = ((((1.987_569_1e-4 * r + 1.398_199_9e-3) * r + 8.333_452e-3) * r + 4.166_579_6e-2) * r
        + 1.666_666_5e-1)
        * r
        + 0.5;
    let y = p * r * r + r + 1.0;
    // 2^n through the exponent bits (n >= -126 here).
    y * f32::from_bits(((n as i32 + 127) as u32) << 23)
}

impl Real for f64 {
    fn of(x: f64) -> Self {
        x
    }

    fn elu_in_place(xs: &mut [f64]) {
        for x in xs {
            if *x <= 0.0 {
                *x = x.exp_m1();
            }
        }
    }
}

/// `c = a b + beta c` on the `gemm` crate for strided matrices, single-threaded (kumi
/// parallelises over blocks of rows instead, which keeps results independent of the thread
/// count).
///
/// # Safety
/// Every index `(i, j)` of the three matrices, with the given dimensions and strides, is in
/// bounds of its slice ([`matmul`] checks this).
#[allow(clippy::too_many_arguments)]
unsafe fn generic_gemm<T: Real>(
    m: usize,
    k: usize,
    n: usize,
    a: &[T],
    (ar, ac): (isize, isize),
    b: &[T],
    (br, bc): (isize, isize),
    beta: T,
    c: &mut [T],
    (cr, cc): (isize, isize),
) {
    // gemm's convention: dst = alpha dst + beta lhs rhs, column stride before row stride.
    let read_dst = beta != T::zero();
    // SAFETY: the caller guarantees the bounds.
    unsafe {
        gemm::gemm(
            m,
            n,
            k,
            c.as_mut_ptr(),
            cc,
            cr,
            read_dst,
            a.as_ptr(),
            ac,
            ar,
            b.as_ptr(),
            bc,
            br,
            beta,
            T::one(),
            false,
            false,
            false,
            gemm::Parallelism::None,
        )
    }
}

/// A read-only view of a row-major `rows x cols` matrix, possibly transposed.
#[derive(Debug, Clone, Copy)]
pub struct Mat<'a, T> {
    pub data: &'a [T],
    pub rows: usize,
    pub cols: usize,
    /// Row-major storage of the matrix whose transpose this view is.
    pub transposed: bool,
}

impl<'a, T> Mat<'a, T> {
    /// A row-major `rows x cols` matrix.
    pub fn new(data: &'a [T], rows: usize, cols: usize) -> Self {
        Self {
            data,
            rows,
            cols,
            transposed: false,
        }
    }

    /// The transpose (no copy).
    pub fn t(self) -> Self {
        Self {
            rows: self.cols,
            cols: self.rows,
            transposed: !self.transposed,
            ..self
        }
    }

    /// (row stride, column stride) of the logical matrix.
    fn strides(&self) -> (isize, isize) {
        if self.transposed {
            (1, self.rows as isize)
        } else {
            (self.cols as isize, 1)
        }
    }
}

/// `c = a b` (`accumulate`: `c += a b`) with `c` row-major `a.rows x b.cols`.
///
/// # Panics
/// If the shapes do not agree or a slice is shorter than its shape (a programming error).
pub fn matmul<T: Real>(a: Mat<T>, b: Mat<T>, c: &mut [T], accumulate: bool) {
    assert_eq!(a.cols, b.rows, "inner dimensions differ");
    assert!(a.data.len() >= a.rows * a.cols, "left matrix too short");
    assert!(b.data.len() >= b.rows * b.cols, "right matrix too short");
    assert!(c.len() >= a.rows * b.cols, "output too short");
    let beta = if accumulate { T::one() } else { T::zero() };
    // SAFETY: the asserts above bound every index of the three views.
    unsafe {
        generic_gemm(
            a.rows,
            a.cols,
            b.cols,
            a.data,
            a.strides(),
            b.data,
            b.strides(),
            beta,
            c,
            (b.cols as isize, 1),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn products_and_transposes_by_hand() {
        // a = [[1, 2, 3], [4, 5, 6]], b = [[1, 0], [0, 1], [1, 1]]
        let a = [1.0_f32, 2.0, 3.0, 4.0, 5.0, 6.0];
        let b = [1.0_f32, 0.0, 0.0, 1.0, 1.0, 1.0];
        let mut c = [0.0_f32; 4];
        matmul(Mat::new(&a, 2, 3), Mat::new(&b, 3, 2), &mut c, false);
        assert_eq!(c, [4.0, 5.0, 10.0, 11.0]);
        // accumulate: c += a b
        matmul(Mat::new(&a, 2, 3), Mat::new(&b, 3, 2), &mut c, true);
        assert_eq!(c, [8.0, 10.0, 20.0, 22.0]);
        // a^T a (3 x 3)
        let mut g = [0.0_f64; 9];
        let a64: Vec<f64> = a.iter().map(|&x| f64::from(x)).collect();
        matmul(
            Mat::new(&a64, 2, 3).t(),
            Mat::new(&a64, 2, 3),
            &mut g,
            false,
        );
        assert_eq!(g, [17.0, 22.0, 27.0, 22.0, 29.0, 36.0, 27.0, 36.0, 45.0]);
    }

    #[test]
    fn the_fast_elu_matches_the_library_exponential() {
        let xs: Vec<f32> = (0..20_000).map(|i| -90.0 + i as f32 * 0.0046).collect();
        let mut fast = xs.clone();
        f32::elu_in_place(&mut fast);
        for (x, y) in xs.iter().zip(&fast) {
            let want = if *x > 0.0 {
                f64::from(*x)
            } else {
                f64::from(*x).exp_m1()
            };
            assert!(
                (f64::from(*y) - want).abs() <= 2e-7 * want.abs().max(1.0),
                "elu({x}) = {y}, not {want}"
            );
        }
    }

    #[test]
    #[should_panic(expected = "inner dimensions differ")]
    fn mismatched_shapes_are_refused() {
        let mut c = [0.0_f32; 4];
        matmul(
            Mat::new(&[0.0; 6], 2, 3),
            Mat::new(&[0.0; 4], 2, 2),
            &mut c,
            false,
        );
    }
}
