//! The gaze field of a set of social charges at one time instant (thesis Sec 7.2).
//!
//! A social charge `Q = (q, r)` (magnitude `q ≥ 0`, position `r`) induces at `x` the field
//! `S(x) = q (r − x) / ‖r − x‖³` (Eq 7.5, the normalising constant `K` set to 1). The net
//! field selects the strongest charge, `S(x) = argmax_{Sᵢ} ‖Sᵢ(x)‖` (Eq 7.6, a max, not
//! the electric sum), and the gaze direction at `x` is distributed as the mixture
//! `Σᵢ πᵢ V(v | Sᵢ/‖Sᵢ‖, κ)` with `πᵢ = ‖Sᵢ‖ / Σₖ ‖Sₖ‖` (Eq 7.7).
//!
//! **A charge exactly at `x`** has no direction there (`r − x = 0`, Eq 7.5 is 0/0 times ∞):
//! it is left out of the mixture at that point (a member does not look at itself). When
//! every charge sits at `x` (or every charge left has `q = 0`) the gaze direction at `x`
//! is uniform on the sphere: density `1/(4π)`, no most likely direction (`None`).

use nalgebra::Vector3;
use std::f64::consts::PI;

use super::vmf::log_density_cos;
use crate::error::{ensure_finite, Error, Result};

/// A social charge `Q = (q, r)` (Table 7.1): `magnitude q ≥ 0`, `position r` in metres.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SocialCharge {
    /// Location `r` of the charge (metres, world frame).
    pub position: Vector3<f64>,
    /// Magnitude `q ≥ 0`: how strongly the charge draws attention (the EM sets it to the
    /// expected number of members looking at it, `qᵢ = Σⱼ γᵢⱼ`).
    pub magnitude: f64,
}

impl SocialCharge {
    /// A charge at `position` with magnitude `magnitude`.
    pub fn new(position: Vector3<f64>, magnitude: f64) -> Self {
        Self {
            position,
            magnitude,
        }
    }
}

/// One component of the mixture of Eq 7.7 at a point: weight `πᵢ` and mean direction
/// `Sᵢ/‖Sᵢ‖`, for charge `index`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Component {
    /// Index of the charge in the field's list.
    pub index: usize,
    /// `ln πᵢ` (`−∞` for a charge of magnitude 0).
    pub log_weight: f64,
    /// Unit vector from the point towards the charge.
    pub direction: Vector3<f64>,
}

/// Checks a list of charges: non-empty, finite positions, finite magnitudes `≥ 0`, at
/// least one positive.
pub fn validate_charges(charges: &[SocialCharge]) -> Result<()> {
    if charges.is_empty() {
        return Err(Error::invalid(
            "charges",
            "at least one social charge is needed to define a gaze field",
        ));
    }
    for (i, c) in charges.iter().enumerate() {
        ensure_finite("charges", c.position.as_slice()).map_err(|_| {
            Error::invalid("charges", format!("charge {i} has a non-finite position"))
        })?;
        if !(c.magnitude.is_finite() && c.magnitude >= 0.0) {
            return Err(Error::invalid(
                "charges",
                format!(
                    "charge {i} has magnitude {} (must be finite and >= 0)",
                    c.magnitude
                ),
            ));
        }
    }
    if charges.iter().all(|c| c.magnitude == 0.0) {
        return Err(Error::invalid(
            "charges",
            "every charge has magnitude 0: the field is zero everywhere",
        ));
    }
    Ok(())
}

/// Checks a concentration: finite and `> 0`.
pub fn validate_kappa(kappa: f64) -> Result<()> {
    if !(kappa.is_finite() && kappa > 0.0) {
        return Err(Error::invalid(
            "kappa",
            format!("the vMF concentration must be finite and > 0, got {kappa}"),
        ));
    }
    Ok(())
}

/// The field of one charge at `x` (Eq 7.5 with `K = 1`): `q (r − x)/‖r − x‖³`, or `None`
/// at `x = r`, where it is undefined.
#[inline]
pub fn charge_field(charge: &SocialCharge, x: &Vector3<f64>) -> Option<Vector3<f64>> {
    let d = charge.position - x;
    let n2 = d.norm_squared();
    if n2 == 0.0 {
        return None;
    }
    Some(d * (charge.magnitude / (n2 * n2.sqrt())))
}

/// The mixture components of Eq 7.7 at `x`, in charge order, leaving out charges located
/// exactly at `x`. `ln πᵢ = ln qᵢ − 2 ln ‖rᵢ − x‖ − ln Σₖ qₖ/‖rₖ − x‖²` (the inverse-square
/// prior). Empty when no charge defines a direction at `x`.
pub fn components(charges: &[SocialCharge], x: &Vector3<f64>, out: &mut Vec<Component>) {
    out.clear();
    let mut max_lw = f64::NEG_INFINITY;
    for (index, c) in charges.iter().enumerate() {
        let d = c.position - x;
        let n2 = d.norm_squared();
        if n2 == 0.0 || !n2.is_finite() {
            continue;
        }
        let lw = c.magnitude.ln() - n2.ln();
        max_lw = max_lw.max(lw);
        out.push(Component {
            index,
            log_weight: lw,
            direction: d / n2.sqrt(),
        });
    }
    if max_lw == f64::NEG_INFINITY {
        out.clear();
        return;
    }
    let lse = max_lw
        + out
            .iter()
            .map(|c| (c.log_weight - max_lw).exp())
            .sum::<f64>()
            .ln();
    for c in out.iter_mut() {
        c.log_weight -= lse;
    }
}

/// `ln p(v | x, {Qᵢ})` of Eq 7.7 for a unit `v`, from precomputed components; the uniform
/// `−ln 4π` when there are none.
pub fn log_density_from(components: &[Component], kappa: f64, v: &Vector3<f64>) -> f64 {
    if components.is_empty() {
        return -(4.0 * PI).ln();
    }
    let terms = components
        .iter()
        .map(|c| c.log_weight + log_density_cos(c.direction.dot(v), kappa));
    log_sum_exp(terms)
}

/// `ln Σ exp(aᵢ)` without overflow; `−∞` for an empty or all-`−∞` input.
pub fn log_sum_exp(terms: impl Iterator<Item = f64> + Clone) -> f64 {
    let m = terms.clone().fold(f64::NEG_INFINITY, f64::max);
    if m == f64::NEG_INFINITY {
        return m;
    }
    m + terms.map(|a| (a - m).exp()).sum::<f64>().ln()
}

/// Most likely direction of the mixture (Eq 7.3) from its components: ascent from every
/// component mean by the fixed point `v ← normalize(Σᵢ πᵢ e^{κ μᵢᵀv} μᵢ)` (monotone, since
/// the mixture is convex in `v`), keeping the best mode. `None` without components.
pub fn mode_from(components: &[Component], kappa: f64) -> Option<Vector3<f64>> {
    let mut best: Option<(f64, Vector3<f64>)> = None;
    for start in components {
        if start.log_weight == f64::NEG_INFINITY {
            continue;
        }
        let mut v = start.direction;
        for _ in 0..200 {
            let logs: Vec<f64> = components
                .iter()
                .map(|c| c.log_weight + kappa * c.direction.dot(&v))
                .collect();
            let m = logs.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            let mut s = Vector3::zeros();
            for (c, l) in components.iter().zip(&logs) {
                s += c.direction * (l - m).exp();
            }
            let n = s.norm();
            if n == 0.0 {
                break;
            }
            let next = s / n;
            let step = (next - v).norm();
            v = next;
            if step < 1e-13 {
                break;
            }
        }
        let ld = log_density_from(components, kappa, &v);
        if best.as_ref().map_or(true, |(b, _)| ld > *b) {
            best = Some((ld, v));
        }
    }
    best.map(|(_, v)| v)
}

/// The gaze field of a set of charges at one time instant with a vMF concentration `κ`.
#[derive(Debug, Clone, PartialEq)]
pub struct GazeField {
    charges: Vec<SocialCharge>,
    kappa: f64,
}

impl GazeField {
    /// Validates the charges ([`validate_charges`]) and `κ > 0`.
    pub fn new(charges: Vec<SocialCharge>, kappa: f64) -> Result<Self> {
        validate_charges(&charges)?;
        validate_kappa(kappa)?;
        Ok(Self { charges, kappa })
    }

    /// The charges.
    pub fn charges(&self) -> &[SocialCharge] {
        &self.charges
    }

    /// The vMF concentration `κ`.
    pub fn kappa(&self) -> f64 {
        self.kappa
    }

    /// The field of every charge at `x` (Eq 7.5); `None` for a charge located at `x`.
    pub fn fields(&self, x: &Vector3<f64>) -> Vec<Option<Vector3<f64>>> {
        self.charges.iter().map(|c| charge_field(c, x)).collect()
    }

    /// The selective net field (Eq 7.6/7.9): the single-charge field of largest norm and
    /// its charge index, or `None` when no charge defines a field at `x`. Ties go to the
    /// lower index.
    pub fn net_field(&self, x: &Vector3<f64>) -> Option<(usize, Vector3<f64>)> {
        let mut best: Option<(usize, Vector3<f64>)> = None;
        for (i, c) in self.charges.iter().enumerate() {
            if let Some(s) = charge_field(c, x) {
                if best.as_ref().map_or(true, |(_, b)| s.norm() > b.norm()) {
                    best = Some((i, s));
                }
            }
        }
        best
    }

    /// The mixture components of Eq 7.7 at `x`.
    pub fn components(&self, x: &Vector3<f64>) -> Vec<Component> {
        let mut out = Vec::with_capacity(self.charges.len());
        components(&self.charges, x, &mut out);
        out
    }

    /// `ln p(v | x)` (Eq 7.7). `v` must be a unit vector and both finite.
    pub fn log_density(&self, x: &Vector3<f64>, v: &Vector3<f64>) -> Result<f64> {
        ensure_finite("x", x.as_slice())?;
        check_unit("v", v)?;
        Ok(log_density_from(&self.components(x), self.kappa, v))
    }

    /// The most likely gaze direction at `x` (Eq 7.3), or `None` when the direction is
    /// uniform there (every charge at `x`).
    pub fn most_likely_direction(&self, x: &Vector3<f64>) -> Result<Option<Vector3<f64>>> {
        ensure_finite("x", x.as_slice())?;
        Ok(mode_from(&self.components(x), self.kappa))
    }
}

/// Fails unless `v` is finite and of unit length within 1e-6.
pub fn check_unit(arg: &str, v: &Vector3<f64>) -> Result<()> {
    ensure_finite(arg, v.as_slice())?;
    if (v.norm() - 1.0).abs() > 1e-6 {
        return Err(Error::invalid(
            arg,
            format!("must be a unit vector, has norm {}", v.norm()),
        ));
    }
    Ok(())
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    fn two() -> GazeField {
        GazeField::new(
            vec![
                SocialCharge::new(Vector3::new(0.0, 0.0, 0.0), 3.0),
                SocialCharge::new(Vector3::new(4.0, 0.0, 0.0), 1.0),
            ],
            20.0,
        )
        .unwrap()
    }

    #[test]
    fn single_charge_field_is_inverse_square_towards_charge() {
        let c = SocialCharge::new(Vector3::new(1.0, 2.0, 3.0), 2.0);
        let x = Vector3::new(1.0, 2.0, 1.0);
        let s = charge_field(&c, &x).unwrap();
        assert_relative_eq!(s, Vector3::new(0.0, 0.0, 2.0 / 4.0), epsilon = 1e-15);
        let x2 = Vector3::new(1.0, 2.0, -1.0);
        assert_relative_eq!(
            s.norm() / charge_field(&c, &x2).unwrap().norm(),
            4.0,
            epsilon = 1e-12
        );
        assert!(charge_field(&c, &c.position).is_none());
    }

    #[test]
    fn net_field_selects_not_sums() {
        let f = two();
        // Near the second (weaker) charge its field dominates.
        let x = Vector3::new(3.5, 0.5, 0.0);
        let (i, s) = f.net_field(&x).unwrap();
        assert_eq!(i, 1);
        assert_relative_eq!(s, charge_field(&f.charges()[1], &x).unwrap());
        // The sum would point elsewhere: the selected field is exactly one charge's field.
        let sum = f
            .fields(&x)
            .into_iter()
            .flatten()
            .fold(Vector3::zeros(), |a, b| a + b);
        assert!((sum.normalize() - s.normalize()).norm() > 1e-3);
        let (i0, _) = f.net_field(&Vector3::new(1.0, 0.0, 1.0)).unwrap();
        assert_eq!(i0, 0);
    }

    #[test]
    fn mixture_weights_follow_inverse_square_and_integrate_to_one() {
        let f = two();
        let x = Vector3::new(1.0, 1.0, 0.0);
        let comps = f.components(&x);
        let s: Vec<f64> = f
            .fields(&x)
            .into_iter()
            .map(|s| s.unwrap().norm())
            .collect();
        let tot = s[0] + s[1];
        assert_relative_eq!(comps[0].log_weight.exp(), s[0] / tot, epsilon = 1e-12);
        assert_relative_eq!(comps[1].log_weight.exp(), s[1] / tot, epsilon = 1e-12);
        // Integrate the density over the sphere on a fine (θ, φ) grid.
        let (nt, np) = (800, 800);
        let mut mass = 0.0;
        for a in 0..nt {
            let th = (a as f64 + 0.5) * PI / nt as f64;
            for b in 0..np {
                let ph = (b as f64 + 0.5) * 2.0 * PI / np as f64;
                let v = Vector3::new(th.sin() * ph.cos(), th.sin() * ph.sin(), th.cos());
                mass += f.log_density(&x, &v).unwrap().exp() * th.sin();
            }
        }
        mass *= (PI / nt as f64) * (2.0 * PI / np as f64);
        assert_relative_eq!(mass, 1.0, epsilon = 1e-3);
    }

    #[test]
    fn most_likely_direction_matches_brute_force() {
        for kappa in [0.8, 3.0, 20.0] {
            let f = GazeField::new(two().charges().to_vec(), kappa).unwrap();
            for x in [
                Vector3::new(1.0, 1.0, 0.0),
                Vector3::new(2.0, 0.3, 0.4),
                Vector3::new(-1.0, -2.0, 1.0),
            ] {
                let v = f.most_likely_direction(&x).unwrap().unwrap();
                let best = f.log_density(&x, &v).unwrap();
                // No grid direction does better.
                let n = 300;
                for a in 0..n {
                    let th = (a as f64 + 0.5) * PI / n as f64;
                    for b in 0..2 * n {
                        let ph = b as f64 * PI / n as f64;
                        let u = Vector3::new(th.sin() * ph.cos(), th.sin() * ph.sin(), th.cos());
                        assert!(f.log_density(&x, &u).unwrap() <= best + 1e-9);
                    }
                }
            }
        }
        // One charge: exactly towards it.
        let f = GazeField::new(
            vec![SocialCharge::new(Vector3::new(0.0, 3.0, 4.0), 1.0)],
            5.0,
        )
        .unwrap();
        let v = f.most_likely_direction(&Vector3::zeros()).unwrap().unwrap();
        assert_relative_eq!(v, Vector3::new(0.0, 0.6, 0.8), epsilon = 1e-14);
    }

    #[test]
    fn member_at_a_charge() {
        let f = two();
        let at = f.charges()[0].position;
        // The charge at x is left out: the density is the other charge's vMF alone.
        let comps = f.components(&at);
        assert_eq!(comps.len(), 1);
        assert_eq!(comps[0].index, 1);
        assert_relative_eq!(comps[0].log_weight, 0.0);
        let v = f.most_likely_direction(&at).unwrap().unwrap();
        assert_relative_eq!(v, Vector3::x(), epsilon = 1e-14);
        // A single charge at x: uniform density, no direction.
        let g = GazeField::new(vec![SocialCharge::new(at, 1.0)], 5.0).unwrap();
        assert!(g.most_likely_direction(&at).unwrap().is_none());
        assert_relative_eq!(g.log_density(&at, &Vector3::z()).unwrap(), -(4.0 * PI).ln());
        assert!(g.net_field(&at).is_none());
    }

    #[test]
    fn bad_input_is_refused() {
        let c = vec![SocialCharge::new(Vector3::zeros(), 1.0)];
        assert!(matches!(
            GazeField::new(vec![], 1.0),
            Err(Error::InvalidInput { .. })
        ));
        for k in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            let e = GazeField::new(c.clone(), k).unwrap_err();
            assert!(matches!(e, Error::InvalidInput { ref arg, .. } if arg == "kappa"));
        }
        let nan = vec![SocialCharge::new(Vector3::new(f64::NAN, 0.0, 0.0), 1.0)];
        assert!(GazeField::new(nan, 1.0).is_err());
        assert!(GazeField::new(vec![SocialCharge::new(Vector3::zeros(), -1.0)], 1.0).is_err());
        assert!(GazeField::new(vec![SocialCharge::new(Vector3::zeros(), 0.0)], 1.0).is_err());
        let f = GazeField::new(c, 1.0).unwrap();
        assert!(f
            .log_density(&Vector3::new(f64::NAN, 0.0, 0.0), &Vector3::z())
            .is_err());
        assert!(f
            .log_density(&Vector3::x(), &Vector3::new(0.0, 0.0, 2.0))
            .is_err());
        assert!(f
            .most_likely_direction(&Vector3::new(0.0, f64::NAN, 0.0))
            .is_err());
    }
}
