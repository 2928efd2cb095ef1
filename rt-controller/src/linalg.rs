//! Allocation-free small matrix products. nalgebra sends products of
//! dynamically sized matrices to `matrixmultiply`, which allocates a packing
//! buffer on every call; for the 6×7 and 7×7 sizes of the control step plain
//! loops are as fast and never allocate.

use nalgebra::{Dim, Matrix, RawStorage, RawStorageMut};

/// `out = a · b`.
pub fn mul_into<R1, C1, S1, R2, C2, S2, R3, C3, S3>(
    a: &Matrix<f64, R1, C1, S1>,
    b: &Matrix<f64, R2, C2, S2>,
    out: &mut Matrix<f64, R3, C3, S3>,
) where
    R1: Dim,
    C1: Dim,
    S1: RawStorage<f64, R1, C1>,
    R2: Dim,
    C2: Dim,
    S2: RawStorage<f64, R2, C2>,
    R3: Dim,
    C3: Dim,
    S3: RawStorageMut<f64, R3, C3>,
{
    let (m, k) = a.shape();
    let n = b.ncols();
    assert!(
        b.nrows() == k && out.shape() == (m, n),
        "mul_into: shape mismatch"
    );
    for j in 0..n {
        for i in 0..m {
            let mut s = 0.0;
            for l in 0..k {
                s += a[(i, l)] * b[(l, j)];
            }
            out[(i, j)] = s;
        }
    }
}

/// `out = aᵀ · b`.
pub fn tr_mul_into<R1, C1, S1, R2, C2, S2, R3, C3, S3>(
    a: &Matrix<f64, R1, C1, S1>,
    b: &Matrix<f64, R2, C2, S2>,
    out: &mut Matrix<f64, R3, C3, S3>,
) where
    R1: Dim,
    C1: Dim,
    S1: RawStorage<f64, R1, C1>,
    R2: Dim,
    C2: Dim,
    S2: RawStorage<f64, R2, C2>,
    R3: Dim,
    C3: Dim,
    S3: RawStorageMut<f64, R3, C3>,
{
    let (k, m) = a.shape();
    let n = b.ncols();
    assert!(
        b.nrows() == k && out.shape() == (m, n),
        "tr_mul_into: shape mismatch"
    );
    for j in 0..n {
        for i in 0..m {
            let mut s = 0.0;
            for l in 0..k {
                s += a[(l, i)] * b[(l, j)];
            }
            out[(i, j)] = s;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{DMatrix, Matrix6xX};

    #[test]
    fn products_match_nalgebra() {
        let a = Matrix6xX::from_fn(7, |i, j| (i as f64 - 2.0 * j as f64).sin());
        let b = DMatrix::from_fn(7, 7, |i, j| (i * j) as f64 * 0.1 - 1.0);
        let mut out = Matrix6xX::zeros(7);
        mul_into(&a, &b, &mut out);
        assert!((out - &a * &b).norm() < 1e-12);
        let mut out = DMatrix::zeros(7, 7);
        tr_mul_into(&a, &a, &mut out);
        assert!((out - a.transpose() * &a).norm() < 1e-12);
    }
}
