//! Many samples at once: the regressor and the inverse dynamics of
//! [`LANES`] samples per pass, structure of arrays, one SIMD lane per sample
//! (`wide::f64x4`: AVX where the build enables it, two SSE2 halves
//! otherwise). No allocation per pass; every sample goes through the same
//! lane code wherever it sits in a batch, so results do not depend on
//! chunking or the thread count. They agree with the per-sample
//! [`regressor`](super::regressor) and [`rnea`](super::rnea) to round-off.
//!
//! The regressor is reorganised, not only vectorised. The per-sample code
//! carries each link's 3 × 10 wrench regressor back through every joint
//! below it (two 3×3 by 3×10 products per pair). Here each joint j's axis
//! u and lever v = u × (o_i − o_j) are carried forward into link i's frame
//! instead (two 3×3 by vector products per pair), and joint j's row for
//! link i is u·n_i + v·f_i, written out per column:
//!   inertia   [u₀ω̇₀, u₀ω̇₁+u₁ω̇₀, …, u₂ω̇₂] + the same of (s, ω), s = u × ω,
//!   moments   a × u + v × ω̇ + ω × (ω × v),
//!   mass      v · a.

use nalgebra::Matrix3;
use wide::f64x4;

use super::model::MAX_JOINTS;
use super::torque_regressor::{coupled, friction_values, FrictionTerms, RegressorTerms};
use super::Model;

/// Samples per pass.
pub const LANES: usize = 4;

type V = f64x4;

#[derive(Clone, Copy, Debug)]
struct V3([V; 3]);

impl V3 {
    const ZERO: V3 = V3([V::ZERO; 3]);

    fn splat(v: &nalgebra::Vector3<f64>) -> V3 {
        V3([V::splat(v.x), V::splat(v.y), V::splat(v.z)])
    }
    #[inline(always)]
    fn add(self, o: V3) -> V3 {
        V3([self.0[0] + o.0[0], self.0[1] + o.0[1], self.0[2] + o.0[2]])
    }
    #[inline(always)]
    fn scale(self, s: V) -> V3 {
        V3([self.0[0] * s, self.0[1] * s, self.0[2] * s])
    }
    #[inline(always)]
    fn cross(self, o: V3) -> V3 {
        let (a, b) = (self.0, o.0);
        V3([
            a[1] * b[2] - a[2] * b[1],
            a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0],
        ])
    }
    #[inline(always)]
    fn dot(self, o: V3) -> V {
        self.0[0] * o.0[0] + self.0[1] * o.0[1] + self.0[2] * o.0[2]
    }
}

/// A rotation per lane, row-major.
#[derive(Clone, Copy)]
struct M3([[V; 3]; 3]);

impl M3 {
    #[inline(always)]
    fn mul(&self, x: V3) -> V3 {
        let r = &self.0;
        V3([
            r[0][0] * x.0[0] + r[0][1] * x.0[1] + r[0][2] * x.0[2],
            r[1][0] * x.0[0] + r[1][1] * x.0[1] + r[1][2] * x.0[2],
            r[2][0] * x.0[0] + r[2][1] * x.0[1] + r[2][2] * x.0[2],
        ])
    }
    #[inline(always)]
    fn tmul(&self, x: V3) -> V3 {
        let r = &self.0;
        V3([
            r[0][0] * x.0[0] + r[1][0] * x.0[1] + r[2][0] * x.0[2],
            r[0][1] * x.0[0] + r[1][1] * x.0[1] + r[2][1] * x.0[2],
            r[0][2] * x.0[0] + r[1][2] * x.0[1] + r[2][2] * x.0[2],
        ])
    }
}

/// One joint's constants: R(q) = A + B·sin q + C·(1 − cos q), the joint
/// origin rotation times Rodrigues' formula about the axis.
#[derive(Clone, Debug)]
struct JointConst {
    a: [[f64; 3]; 3],
    b: [[f64; 3]; 3],
    c: [[f64; 3]; 3],
    axis: V3,
    origin: V3,
    mass: V,
    first_moment: V3,
    inertia: [[f64; 3]; 3],
}

fn rows(m: &Matrix3<f64>) -> [[f64; 3]; 3] {
    [0, 1, 2].map(|r| [0, 1, 2].map(|c| m[(r, c)]))
}

/// A model prepared for [`LANES`] samples per pass.
#[derive(Clone, Debug)]
pub struct Batched {
    model: Model,
    joints: Vec<JointConst>,
}

/// Per-pass buffers of [`Batched`]: one per thread, reused for every pass.
pub struct BatchData {
    rot: Vec<M3>,
    w: Vec<V3>,
    dw: Vec<V3>,
    acc: Vec<V3>,
    u: Vec<V3>,
    v: Vec<V3>,
    force: Vec<V3>,
    moment: Vec<V3>,
    /// The regressor of the last pass, n × count row-major, a lane per sample.
    phi: Vec<V>,
    count: usize,
}

impl BatchData {
    /// Entry (row `j`, column `c`) of the last regressor pass, one value per lane.
    #[inline]
    pub fn phi(&self, j: usize, c: usize) -> [f64; LANES] {
        self.phi[j * self.count + c].to_array()
    }
}

impl Batched {
    pub fn new(model: &Model) -> Batched {
        let joints = model
            .joints
            .iter()
            .zip(&model.links)
            .map(|(j, l)| {
                let k = j.axis.into_inner();
                let kx = Matrix3::new(0.0, -k.z, k.y, k.z, 0.0, -k.x, -k.y, k.x, 0.0);
                JointConst {
                    a: rows(&j.origin_rot),
                    b: rows(&(j.origin_rot * kx)),
                    c: rows(&(j.origin_rot * kx * kx)),
                    axis: V3::splat(&k),
                    origin: V3::splat(&j.origin_xyz),
                    mass: V::splat(l.mass),
                    first_moment: V3::splat(&l.first_moment()),
                    inertia: rows(&l.inertia_origin()),
                }
            })
            .collect();
        Batched {
            model: model.clone(),
            joints,
        }
    }

    pub fn dof(&self) -> usize {
        self.joints.len()
    }

    pub fn workspace(&self, terms: RegressorTerms) -> BatchData {
        let n = self.dof();
        let count = terms.count(&self.model);
        BatchData {
            rot: vec![M3([[V::ZERO; 3]; 3]); n],
            w: vec![V3::ZERO; n],
            dw: vec![V3::ZERO; n],
            acc: vec![V3::ZERO; n],
            u: vec![V3::ZERO; n],
            v: vec![V3::ZERO; n],
            force: vec![V3::ZERO; n],
            moment: vec![V3::ZERO; n],
            phi: vec![V::ZERO; n * count],
            count,
        }
    }

    /// Velocities and accelerations of every link from the base outwards,
    /// as `rnea::forward_pass`.
    #[inline(always)]
    fn forward(
        &self,
        ws: &mut BatchData,
        q: &[[f64; LANES]],
        qd: &[[f64; LANES]],
        qdd: &[[f64; LANES]],
        gravity: bool,
    ) {
        let mut w_p = V3::ZERO;
        let mut dw_p = V3::ZERO;
        let mut a_p = if gravity {
            V3::splat(&-self.model.gravity)
        } else {
            V3::ZERO
        };
        for (i, jc) in self.joints.iter().enumerate() {
            let (s, c) = V::new(q[i]).sin_cos();
            let c1 = V::ONE - c;
            let r = M3([0, 1, 2].map(|row| {
                [0, 1, 2]
                    .map(|col| V::splat(jc.a[row][col]) + V::splat(jc.b[row][col]) * s + V::splat(jc.c[row][col]) * c1)
            }));
            let (vd, vdd) = (V::new(qd[i]), V::new(qdd[i]));
            let z = jc.axis;
            let w_in = r.tmul(w_p);
            let zqd = z.scale(vd);
            let w = w_in.add(zqd);
            let dw = r.tmul(dw_p).add(z.scale(vdd)).add(w_in.cross(zqd));
            let p = jc.origin;
            let a = r.tmul(a_p.add(dw_p.cross(p)).add(w_p.cross(w_p.cross(p))));
            ws.rot[i] = r;
            ws.w[i] = w;
            ws.dw[i] = dw;
            ws.acc[i] = a;
            (w_p, dw_p, a_p) = (w, dw, a);
        }
    }

    /// The full regressor Φ(q, q̇, q̈) of one pass (as [`regressor`](super::regressor),
    /// n × `terms.count(model)`), into `ws` ([`BatchData::phi`]). Inputs are per
    /// joint, a lane per sample; `ws` comes from [`Batched::workspace`] with
    /// the same `terms`.
    pub fn regressor(
        &self,
        ws: &mut BatchData,
        q: &[[f64; LANES]],
        qd: &[[f64; LANES]],
        qdd: &[[f64; LANES]],
        terms: RegressorTerms,
    ) {
        let n = self.dof();
        let count = terms.count(&self.model);
        assert!(q.len() == n && qd.len() == n && qdd.len() == n && ws.count == count);
        self.forward(ws, q, qd, qdd, true);
        ws.phi.fill(V::ZERO);
        for i in 0..n {
            let jc = &self.joints[i];
            let r = ws.rot[i];
            // Carry the axes and levers of the joints below into frame i.
            for j in 0..i {
                let (u, v) = (ws.u[j], ws.v[j]);
                ws.u[j] = r.tmul(u);
                ws.v[j] = r.tmul(v.add(u.cross(jc.origin)));
            }
            ws.u[i] = jc.axis;
            ws.v[i] = V3::ZERO;
            let ([w0, w1, w2], dw, a) = (ws.w[i].0, ws.dw[i], ws.acc[i]);
            let [d0, d1, d2] = dw.0;
            let w = ws.w[i];
            for j in 0..=i {
                let (u, v) = (ws.u[j], ws.v[j]);
                let [u0, u1, u2] = u.0;
                let [s0, s1, s2] = u.cross(w).0;
                let moments = a.cross(u).add(v.cross(dw)).add(w.cross(w.cross(v)));
                let row = &mut ws.phi[j * count + 10 * i..j * count + 10 * i + 10];
                row[0] = u0 * d0 + s0 * w0;
                row[1] = u0 * d1 + u1 * d0 + s0 * w1 + s1 * w0;
                row[2] = u0 * d2 + u2 * d0 + s0 * w2 + s2 * w0;
                row[3] = u1 * d1 + s1 * w1;
                row[4] = u1 * d2 + u2 * d1 + s1 * w2 + s2 * w1;
                row[5] = u2 * d2 + s2 * w2;
                row[6..9].copy_from_slice(&moments.0);
                row[9] = v.dot(a);
            }
        }
        self.joint_terms(ws, q, qd, qdd, terms);
    }

    /// Φ's joint terms (rotor, friction, offset, spring), lane by lane:
    /// cheap, and sign/tanh are scalar.
    fn joint_terms(
        &self,
        ws: &mut BatchData,
        q: &[[f64; LANES]],
        qd: &[[f64; LANES]],
        qdd: &[[f64; LANES]],
        terms: RegressorTerms,
    ) {
        let n = self.dof();
        let count = ws.count;
        let per = terms.per_joint();
        for j in 0..n {
            let mut c = 10 * n + per * j;
            let base = j * count;
            if terms.rotor {
                ws.phi[base + c] = V::new(qdd[j]);
                c += 1;
            }
            if terms.friction != FrictionTerms::None {
                let mut cols = [[0.0; LANES]; super::torque_regressor::FRICTION_COLUMNS];
                let mut width = 0;
                for l in 0..LANES {
                    let (vals, w) = friction_values(terms.friction, &self.model.friction[j], qd[j][l]);
                    for (k, x) in vals.iter().enumerate() {
                        cols[k][l] = *x;
                    }
                    width = w;
                }
                for (k, col) in cols.iter().take(width).enumerate() {
                    ws.phi[base + c + k] = V::new(*col);
                }
                c += width;
            }
            if terms.offset {
                ws.phi[base + c] = V::ONE;
            }
        }
        if let Some(sp) = terms.spring {
            let c0 = sp.joint * count + n * (10 + per);
            for h in 1..=sp.harmonics as usize {
                let (mut s, mut co) = ([0.0; LANES], [0.0; LANES]);
                for l in 0..LANES {
                    (s[l], co[l]) = (h as f64 * q[sp.joint][l]).sin_cos();
                }
                ws.phi[c0 + 2 * (h - 1)] = V::new(co);
                ws.phi[c0 + 2 * (h - 1) + 1] = V::new(s);
            }
        }
        if !self.model.couplings.is_empty() {
            let (mut v, mut a) = ([0.0; MAX_JOINTS], [0.0; MAX_JOINTS]);
            for l in 0..LANES {
                for j in 0..n {
                    (v[j], a[j]) = (qd[j][l], qdd[j][l]);
                }
                coupled(&self.model, (&v[..n], &a[..n]), terms, &mut |row, col, x| {
                    let mut lanes = ws.phi[row * count + col].to_array();
                    lanes[l] = x;
                    ws.phi[row * count + col] = V::new(lanes);
                });
            }
        }
    }

    /// Joint torques of one pass (as [`rnea`](super::rnea): gravity, rotors
    /// and friction included), N·m, into `tau[j]`, a lane per sample.
    pub fn rnea(
        &self,
        ws: &mut BatchData,
        q: &[[f64; LANES]],
        qd: &[[f64; LANES]],
        qdd: &[[f64; LANES]],
        tau: &mut [[f64; LANES]],
    ) {
        let n = self.dof();
        assert!(q.len() == n && qd.len() == n && qdd.len() == n && tau.len() == n);
        self.forward(ws, q, qd, qdd, true);
        for (i, jc) in self.joints.iter().enumerate() {
            let (w, dw, a, h) = (ws.w[i], ws.dw[i], ws.acc[i], jc.first_moment);
            let io = M3(jc.inertia.map(|row| row.map(V::splat)));
            ws.force[i] = a.scale(jc.mass).add(dw.cross(h)).add(w.cross(w.cross(h)));
            ws.moment[i] = io.mul(dw).add(w.cross(io.mul(w))).add(h.cross(a));
        }
        for i in (1..n).rev() {
            let r = ws.rot[i];
            let f = r.mul(ws.force[i]);
            let m = r.mul(ws.moment[i]).add(self.joints[i].origin.cross(f));
            ws.force[i - 1] = ws.force[i - 1].add(f);
            ws.moment[i - 1] = ws.moment[i - 1].add(m);
        }
        for j in 0..n {
            let t = self.joints[j].axis.dot(ws.moment[j]).to_array();
            let rotor = self.model.drives[j].reflected_inertia();
            let fr = &self.model.friction[j];
            for l in 0..LANES {
                tau[j][l] = t[l] + rotor * qdd[j][l] + fr.torque(qd[j][l]);
            }
        }
        if !self.model.couplings.is_empty() {
            let (mut v, mut a, mut t) = ([0.0; MAX_JOINTS], [0.0; MAX_JOINTS], [0.0; MAX_JOINTS]);
            for l in 0..LANES {
                for j in 0..n {
                    (v[j], a[j], t[j]) = (qd[j][l], qdd[j][l], 0.0);
                }
                self.model
                    .add_coupled_torque(&v[..n], &a[..n], (true, true), &mut t[..n]);
                for j in 0..n {
                    tau[j][l] += t[j];
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dynamics::{regressor, rnea, Data, Spring};
    use nalgebra::DMatrix;

    fn lanes(rng: &mut u64, n: usize, scale: f64) -> Vec<[f64; LANES]> {
        (0..n)
            .map(|_| {
                [0; LANES].map(|_| {
                    *rng = rng.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                    scale * ((*rng >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0)
                })
            })
            .collect()
    }

    /// Every lane equals the per-sample kernels, for every kind of term,
    /// with a coupled wrist and without.
    #[test]
    fn lanes_equal_the_per_sample_kernels() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../fixtures/robots/ur5.toml");
        let mut model = crate::dynamics::load_robot(&path).unwrap();
        model.friction[2].transition = 0.05;
        let mut wrist = model.clone();
        wrist.couplings.push(crate::dynamics::Coupling {
            motor: 5,
            with: vec![(4, -30.0)],
            viscous: 2e-4,
            coulomb: 0.01,
        });
        wrist.drives[5].rotor_inertia = 3e-5;
        for model in [model, wrist] {
            lanes_equal_on(&model);
        }
    }

    fn lanes_equal_on(model: &Model) {
        let n = model.dof();
        let batched = Batched::new(model);
        let mut data = Data::new(model);
        let mut rng = 7u64;
        for terms in [
            RegressorTerms::DEFAULT,
            RegressorTerms {
                rotor: false,
                friction: FrictionTerms::Asymmetric,
                offset: true,
                spring: Some(Spring { joint: 1, harmonics: 3 }),
            },
        ] {
            let mut ws = batched.workspace(terms);
            let count = terms.count(model);
            let mut phi = DMatrix::zeros(n, count);
            let mut tau = vec![[0.0; LANES]; n];
            for _ in 0..25 {
                let (q, qd, qdd) = (
                    lanes(&mut rng, n, 3.0),
                    lanes(&mut rng, n, 2.0),
                    lanes(&mut rng, n, 8.0),
                );
                batched.regressor(&mut ws, &q, &qd, &qdd, terms);
                batched.rnea(&mut ws, &q, &qd, &qdd, &mut tau);
                for l in 0..LANES {
                    let pick = |x: &[[f64; LANES]]| x.iter().map(|v| v[l]).collect::<Vec<_>>();
                    let (ql, qdl, qddl) = (pick(&q), pick(&qd), pick(&qdd));
                    regressor(model, &mut data, &ql, &qdl, &qddl, terms, &mut phi);
                    let scale = phi.amax();
                    for j in 0..n {
                        for c in 0..count {
                            let d = (ws.phi(j, c)[l] - phi[(j, c)]).abs();
                            assert!(
                                d <= 1e-13 * scale,
                                "Φ[{j},{c}] lane {l}: {} vs {}",
                                ws.phi(j, c)[l],
                                phi[(j, c)]
                            );
                        }
                    }
                    let t = rnea(model, &mut data, &ql, &qdl, &qddl);
                    for j in 0..n {
                        assert!(
                            (tau[j][l] - t[j]).abs() <= 1e-12 * t.amax(),
                            "τ[{j}] lane {l}: {} vs {}",
                            tau[j][l],
                            t[j]
                        );
                    }
                }
            }
        }
    }
}
