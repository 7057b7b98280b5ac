//! Least-squares systems too large to hold: a running R factor.
//!
//! For A·θ ≈ b, the pair (R, z) with R upper triangular (p × p) and
//! z = Qᵀb holds everything least squares needs: θ = R⁻¹z, and the
//! residual sum of squares accumulates alongside. A block of new rows — or
//! another recording's pair — is folded in by a QR factorisation of
//! [R z; A b], never by forming AᵀA (which squares the condition number).
//! Recordings can be reduced separately, in parallel, and merged in any
//! grouping: a reduce over small matrices (ARCHITECTURE: keep that door open).

use nalgebra::{DMatrix, DVector};

#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RFactor {
    /// Upper triangular, p × p.
    pub r: DMatrix<f64>,
    /// Qᵀb, length p.
    pub z: DVector<f64>,
    /// Residual sum of squares of the rows folded in so far.
    pub rss: f64,
    /// Rows folded in so far.
    pub rows: usize,
}

impl RFactor {
    pub fn new(p: usize) -> RFactor {
        RFactor {
            r: DMatrix::zeros(p, p),
            z: DVector::zeros(p),
            rss: 0.0,
            rows: 0,
        }
    }

    pub fn parameters(&self) -> usize {
        self.z.len()
    }

    /// Folds in rows `a` (k × p) with right-hand side `b` (k).
    pub fn add_rows(&mut self, a: &DMatrix<f64>, b: &DVector<f64>) {
        let p = self.parameters();
        assert_eq!(a.ncols(), p, "R factor: expected {p} columns");
        assert_eq!(
            a.nrows(),
            b.len(),
            "R factor: rows and right-hand side differ in length"
        );
        self.fold(a, b, 0.0, a.nrows());
    }

    /// Merges another factor of the same parameters (another recording).
    pub fn merge(&mut self, other: &RFactor) {
        assert_eq!(
            other.parameters(),
            self.parameters(),
            "R factor: different parameter counts"
        );
        self.fold(&other.r, &other.z, other.rss, other.rows);
    }

    fn fold(&mut self, a: &DMatrix<f64>, b: &DVector<f64>, rss: f64, rows: usize) {
        let p = self.parameters();
        let k = a.nrows();
        // [R z; A b], QR; the new R and z are the top p rows, the rest of the
        // last column is residual.
        let mut m = DMatrix::zeros(p + k, p + 1);
        m.view_mut((0, 0), (p, p)).copy_from(&self.r);
        m.view_mut((0, p), (p, 1)).copy_from(&self.z);
        m.view_mut((p, 0), (k, p)).copy_from(a);
        m.view_mut((p, p), (k, 1)).copy_from(b);
        let r_all = m.qr().r();
        let n = r_all.nrows();
        self.r = r_all.view((0, 0), (p.min(n), p)).clone_owned();
        if self.r.nrows() < p {
            self.r = self.r.clone().resize_vertically(p, 0.0);
        }
        let zcol = r_all.column(p);
        self.z = DVector::from_fn(p, |i, _| if i < n { zcol[i] } else { 0.0 });
        // The stack's residual: what each part had already left out, plus
        // what the fold leaves (the augmented column's last diagonal entry).
        let tail = if n > p { zcol[p] } else { 0.0 };
        self.rss += rss + tail * tail;
        self.rows += rows;
    }

    /// θ = R⁻¹z (None if R is singular: a parameter is not excited).
    pub fn solve(&self) -> Option<DVector<f64>> {
        self.r.clone().solve_upper_triangular(&self.z)
    }
}
