//! The von Mises–Fisher distribution on the unit sphere S² (thesis Eq 7.7, footnote 2): the
//! spherical analogue of a normal distribution, used for eye-in-head deviation about the
//! direction the gaze field points to.
//!
//! `V(v | μ, κ) = C₃(κ) exp(κ μᵀv)` with `C₃(κ) = κ / (4π sinh κ)`.

use std::f64::consts::PI;

/// Smallest and largest concentration the estimator returns; outside this range the
/// distribution is numerically uniform or a point mass.
pub const KAPPA_MIN: f64 = 1e-8;
/// See [`KAPPA_MIN`].
pub const KAPPA_MAX: f64 = 1e8;

/// `ln C₃(κ) = ln κ − ln 2π − κ − ln(1 − e^{−2κ})`, stable for tiny and huge `κ > 0`.
#[inline]
pub fn log_normalizer(kappa: f64) -> f64 {
    kappa.ln() - (2.0 * PI).ln() - kappa - (-(-2.0 * kappa).exp_m1()).ln()
}

/// `ln V(v | μ, κ)` for unit `v`, `μ`, given `cos = μᵀv`.
#[inline]
pub fn log_density_cos(cos: f64, kappa: f64) -> f64 {
    log_normalizer(kappa) + kappa * cos
}

/// Mean resultant length `A₃(κ) = E[μᵀv] = coth κ − 1/κ`.
pub fn mean_resultant(kappa: f64) -> f64 {
    if kappa < 1e-4 {
        // Series: κ/3 − κ³/45.
        kappa / 3.0 - kappa.powi(3) / 45.0
    } else {
        1.0 / kappa.tanh() - 1.0 / kappa
    }
}

/// Maximum-likelihood concentration for a weighted mean resultant length `r̄ = Σ wᵢ μᵢᵀvᵢ /
/// Σ wᵢ`: solves `A₃(κ) = r̄` by Newton from Banerjee et al.'s approximation, clamped to
/// `[KAPPA_MIN, KAPPA_MAX]` (`r̄ ≤ 0` gives `KAPPA_MIN`, i.e. a uniform distribution).
pub fn kappa_from_resultant(rbar: f64) -> f64 {
    if rbar.is_nan() || rbar <= 0.0 {
        return KAPPA_MIN;
    }
    if rbar >= 1.0 - 1e-12 {
        return KAPPA_MAX;
    }
    let mut k = rbar * (3.0 - rbar * rbar) / (1.0 - rbar * rbar);
    for _ in 0..50 {
        let f = mean_resultant(k) - rbar;
        // A₃'(κ) = 1/κ² − 1/sinh²κ (> 0).
        let sh = k.sinh();
        let d = if k < 1e-3 {
            1.0 / 3.0 - k * k / 15.0
        } else if k > 300.0 {
            1.0 / (k * k)
        } else {
            1.0 / (k * k) - 1.0 / (sh * sh)
        };
        if d.is_nan() || d <= 0.0 {
            break;
        }
        let next = (k - f / d).clamp(k * 0.1, k * 10.0);
        let done = (next - k).abs() <= 1e-12 * k;
        k = next;
        if done {
            break;
        }
    }
    k.clamp(KAPPA_MIN, KAPPA_MAX)
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    /// ∫_{S²} C₃ e^{κ cos θ} dΩ = 2π ∫₋₁¹ C₃ e^{κ c} dc, by Simpson's rule.
    fn total_mass(kappa: f64) -> f64 {
        let n = 20_000;
        let h = 2.0 / n as f64;
        let mut s = 0.0;
        for i in 0..=n {
            let c = -1.0 + i as f64 * h;
            let w = if i == 0 || i == n {
                1.0
            } else if i % 2 == 1 {
                4.0
            } else {
                2.0
            };
            s += w * log_density_cos(c, kappa).exp();
        }
        2.0 * PI * s * h / 3.0
    }

    #[test]
    fn density_integrates_to_one() {
        for k in [1e-6, 0.3, 2.0, 15.0, 80.0] {
            assert_relative_eq!(total_mass(k), 1.0, epsilon = 1e-6);
        }
        // Tiny κ tends to the uniform density 1/(4π).
        assert_relative_eq!(log_normalizer(1e-9), -(4.0 * PI).ln(), epsilon = 1e-8);
        // Huge κ stays finite.
        assert!(log_normalizer(1e7).is_finite());
    }

    #[test]
    fn kappa_round_trip() {
        for k in [0.01, 0.5, 3.0, 20.0, 500.0, 1e5] {
            let r = mean_resultant(k);
            assert_relative_eq!(kappa_from_resultant(r), k, max_relative = 1e-7);
        }
        assert_eq!(kappa_from_resultant(-0.2), KAPPA_MIN);
        assert_eq!(kappa_from_resultant(1.0), KAPPA_MAX);
    }
}
