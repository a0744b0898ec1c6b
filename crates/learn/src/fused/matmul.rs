//! Matrix products on host slices through the `gemm` crate (the kernels candle itself calls,
//! with their run-time choice of AVX-512 / AVX2 / SSE), behind a safe interface: a [`Mat`] can
//! only be made from a slice that holds every element its shape and strides address, so the
//! one `unsafe` call below reads and writes inside its slices.
#![allow(unsafe_code)]

/// A read-only matrix view: element `(r, c)` at `data[r * row_stride + c * col_stride]`.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Mat<'a> {
    data: &'a [f32],
    rows: usize,
    cols: usize,
    row_stride: usize,
    col_stride: usize,
}

impl<'a> Mat<'a> {
    /// The first `rows * cols` elements of `data`, row-major.
    ///
    /// # Panics
    /// When `data` is shorter than `rows * cols` (a programming error in this crate).
    pub(crate) fn rows(data: &'a [f32], rows: usize, cols: usize) -> Self {
        assert!(
            data.len() >= rows * cols,
            "a {rows}x{cols} matrix over {} values",
            data.len()
        );
        Self {
            data,
            rows,
            cols,
            row_stride: cols,
            col_stride: 1,
        }
    }

    /// The transposed view (no copy).
    pub(crate) fn t(self) -> Self {
        Self {
            rows: self.cols,
            cols: self.rows,
            row_stride: self.col_stride,
            col_stride: self.row_stride,
            ..self
        }
    }
}

/// `dst = lhs * rhs` (or `dst += lhs * rhs` with `accumulate`), `dst` row-major
/// `lhs.rows x rhs.cols`, on the calling thread.
///
/// # Panics
/// When the shapes do not chain or `dst` is too short (programming errors in this crate).
pub(crate) fn product(dst: &mut [f32], lhs: Mat<'_>, rhs: Mat<'_>, accumulate: bool) {
    let (m, k, n) = (lhs.rows, lhs.cols, rhs.cols);
    assert_eq!(k, rhs.rows, "a {m}x{k} by {}x{n} product", rhs.rows);
    assert!(
        dst.len() >= m * n,
        "a {m}x{n} product into {} values",
        dst.len()
    );
    if m == 0 || n == 0 {
        return;
    }
    if k == 0 {
        if !accumulate {
            dst[..m * n].fill(0.0);
        }
        return;
    }
    // SAFETY: `Mat::rows` checked that each operand's slice holds `rows * cols` values, and a
    // transposed view addresses the same elements, so every index `r * row_stride + c *
    // col_stride` with `r < rows`, `c < cols` is inside its slice; `dst` holds `m * n` values
    // (asserted) and is written row-major with column stride 1. The operands are shared
    // borrows and `dst` an exclusive one, so they cannot overlap. `Parallelism::None`: the
    // product runs on this thread only.
    unsafe {
        gemm::gemm(
            m,
            n,
            k,
            dst.as_mut_ptr(),
            1,
            n as isize,
            accumulate,
            lhs.data.as_ptr(),
            lhs.col_stride as isize,
            lhs.row_stride as isize,
            rhs.data.as_ptr(),
            rhs.col_stride as isize,
            rhs.row_stride as isize,
            1.0,
            1.0,
            false,
            false,
            false,
            gemm::Parallelism::None,
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn naive(a: &[f32], b: &[f32], m: usize, k: usize, n: usize) -> Vec<f32> {
        let mut out = vec![0.0; m * n];
        for i in 0..m {
            for j in 0..n {
                out[i * n + j] = (0..k).map(|p| a[i * k + p] * b[p * n + j]).sum();
            }
        }
        out
    }

    fn values(n: usize, seed: u32) -> Vec<f32> {
        (0..n as u32)
            .map(|i| (i.wrapping_mul(2_654_435_761).wrapping_add(seed) % 1000) as f32 / 500.0 - 1.0)
            .collect()
    }

    fn close(a: &[f32], b: &[f32]) {
        assert_eq!(a.len(), b.len());
        for (x, y) in a.iter().zip(b) {
            assert!((x - y).abs() < 1e-4, "{x} vs {y}");
        }
    }

    #[test]
    fn products_and_transposed_views_match_the_textbook_product() {
        let (m, k, n) = (5, 7, 3);
        let a = values(m * k, 1);
        let b = values(k * n, 2);
        let mut dst = vec![0.0; m * n];
        product(&mut dst, Mat::rows(&a, m, k), Mat::rows(&b, k, n), false);
        close(&dst, &naive(&a, &b, m, k, n));

        // (B^T A^T)^T = A B: the same product through transposed views of transposed data.
        let at: Vec<f32> = (0..k * m).map(|i| a[(i % m) * k + i / m]).collect();
        let bt: Vec<f32> = (0..n * k).map(|i| b[(i % k) * n + i / k]).collect();
        let mut again = vec![0.0; m * n];
        product(
            &mut again,
            Mat::rows(&at, k, m).t(),
            Mat::rows(&bt, n, k).t(),
            false,
        );
        close(&again, &dst);

        // Accumulating adds the product to what is there.
        let mut twice = dst.clone();
        product(&mut twice, Mat::rows(&a, m, k), Mat::rows(&b, k, n), true);
        close(&twice, &dst.iter().map(|x| 2.0 * x).collect::<Vec<_>>());
    }

    #[test]
    #[should_panic(expected = "product")]
    fn shapes_that_do_not_chain_are_refused() {
        let a = values(6, 1);
        let mut dst = vec![0.0; 4];
        product(&mut dst, Mat::rows(&a, 2, 3), Mat::rows(&a, 2, 3), false);
    }
}
