//! The 6×6 linear algebra of one Gauss–Newton step: a symmetric positive definite solve
//! (Cholesky, A = L·Lᵀ) and a symmetric eigen decomposition (the reconstruct crate's cyclic
//! Jacobi, shared with its 3×3 plane fits) that finds the directions the data do not constrain.
//!
//! Written here rather than taken from nalgebra or faer: the alignment needs exactly one fixed
//! 6×6 solve and decomposition per iteration, glam has no 6×6 type, and fifty lines of
//! textbook code (Golub & Van Loan §4.2) cost less than a linear-algebra dependency.
//! The normal equations carry a positive prior on the diagonal (see `icp`), so the matrix is
//! positive definite and Cholesky, which needs no pivoting, is stable for it; Jacobi is
//! unconditionally stable for symmetric matrices.

/// Solves `a · x = b` for a symmetric positive definite `a` (only its lower triangle is read);
/// `None` if `a` is not positive definite (to working precision).
// Index loops mirror the textbook recurrences.
#[allow(clippy::needless_range_loop)]
pub fn solve_spd6(a: &[[f64; 6]; 6], b: &[f64; 6]) -> Option<[f64; 6]> {
    let mut l = [[0.0f64; 6]; 6];
    for j in 0..6 {
        let mut diag = a[j][j];
        for k in 0..j {
            diag -= l[j][k] * l[j][k];
        }
        if !(diag > 1e-300 && diag.is_finite()) {
            return None;
        }
        let ljj = diag.sqrt();
        l[j][j] = ljj;
        for i in j + 1..6 {
            let mut v = a[i][j];
            for k in 0..j {
                v -= l[i][k] * l[j][k];
            }
            l[i][j] = v / ljj;
        }
    }
    // L·y = b, then Lᵀ·x = y.
    let mut y = [0.0f64; 6];
    for i in 0..6 {
        let mut v = b[i];
        for k in 0..i {
            v -= l[i][k] * y[k];
        }
        y[i] = v / l[i][i];
    }
    let mut x = [0.0f64; 6];
    for i in (0..6).rev() {
        let mut v = y[i];
        for k in i + 1..6 {
            v -= l[k][i] * x[k];
        }
        x[i] = v / l[i][i];
    }
    Some(x)
}

/// Eigenvalues and unit eigenvectors of a symmetric 6×6 matrix (`vectors[i]` belongs to
/// `values[i]`), unsorted: the reconstruct crate's Jacobi solver at N = 6.
pub fn symmetric_eigen6(m: &[[f64; 6]; 6]) -> ([f64; 6], [[f64; 6]; 6]) {
    tacmesh_reconstruct::moments::symmetric_eigen(m)
}

#[cfg(test)]
// Index loops read like the matrix formulas they check.
#[allow(clippy::needless_range_loop)]
mod tests {
    use super::*;

    #[test]
    fn solve_recovers_known_solution() {
        // A = Mᵀ·M + I is symmetric positive definite.
        let mut m = [[0.0f64; 6]; 6];
        for (i, row) in m.iter_mut().enumerate() {
            for (j, v) in row.iter_mut().enumerate() {
                *v = ((i * 7 + j * 3) % 5) as f64 - 2.0;
            }
        }
        let mut a = [[0.0f64; 6]; 6];
        for i in 0..6 {
            for j in 0..6 {
                a[i][j] = (0..6).map(|k| m[k][i] * m[k][j]).sum::<f64>();
            }
            a[i][i] += 1.0;
        }
        let x_true = [1.0, -2.0, 0.5, 3.0, 0.0, -1.5];
        let mut b = [0.0f64; 6];
        for i in 0..6 {
            b[i] = (0..6).map(|j| a[i][j] * x_true[j]).sum();
        }
        let x = solve_spd6(&a, &b).unwrap();
        for i in 0..6 {
            assert!((x[i] - x_true[i]).abs() < 1e-9, "{x:?}");
        }
    }

    #[test]
    fn eigen_decomposition_reconstructs_the_matrix() {
        let mut a = [[0.0f64; 6]; 6];
        for i in 0..6 {
            for j in 0..6 {
                a[i][j] = 1.0 / (1.0 + i as f64 + j as f64) + if i == j { i as f64 } else { 0.0 };
            }
        }
        let (values, vectors) = symmetric_eigen6(&a);
        for i in 0..6 {
            for j in 0..6 {
                let back: f64 = (0..6)
                    .map(|k| values[k] * vectors[k][i] * vectors[k][j])
                    .sum();
                assert!(
                    (back - a[i][j]).abs() < 1e-9,
                    "{i},{j}: {back} vs {}",
                    a[i][j]
                );
            }
        }
    }

    #[test]
    fn solve_refuses_singular_matrix() {
        assert_eq!(solve_spd6(&[[0.0; 6]; 6], &[1.0; 6]), None);
    }
}
