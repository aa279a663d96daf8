//! Evaluating a time-varying gaze field (Eq 7.9) at many points in parallel: each query
//! names the frame whose charges apply. A frame without a field (no charges there) gives
//! `None` / NaN, never an error, so a sequence with gaps can be queried in one call.

use nalgebra::Vector3;
use rayon::prelude::*;

use super::field::{check_unit, components, log_density_from, mode_from, GazeField};
use crate::error::{ensure_finite, Error, Result};

fn check_frames(fields: &[Option<GazeField>], frame: &[usize], n: usize) -> Result<()> {
    if frame.len() != n {
        return Err(Error::invalid(
            "frame",
            format!("needs one frame index per query ({n}), got {}", frame.len()),
        ));
    }
    if let Some(k) = frame.iter().position(|&f| f >= fields.len()) {
        return Err(Error::invalid(
            "frame",
            format!("query {k} names frame {} of {}", frame[k], fields.len()),
        ));
    }
    Ok(())
}

/// Most likely gaze direction (Eq 7.3) at `points[k]` under the field of `frame[k]`;
/// `None` where that frame has no field or the direction is uniform (every charge at the
/// point).
pub fn predict(
    fields: &[Option<GazeField>],
    frame: &[usize],
    points: &[Vector3<f64>],
) -> Result<Vec<Option<Vector3<f64>>>> {
    check_frames(fields, frame, points.len())?;
    for x in points {
        ensure_finite("points", x.as_slice())?;
    }
    Ok(points
        .par_iter()
        .zip(frame.par_iter())
        .map_init(Vec::new, |comps, (x, &f)| {
            let field = fields[f].as_ref()?;
            components(field.charges(), x, comps);
            mode_from(comps, field.kappa())
        })
        .collect())
}

/// `ln p(v[k] | p[k])` (Eq 7.7) under the field of `frame[k]`; NaN where that frame has no
/// field.
pub fn log_density(
    fields: &[Option<GazeField>],
    frame: &[usize],
    p: &[Vector3<f64>],
    v: &[Vector3<f64>],
) -> Result<Vec<f64>> {
    check_frames(fields, frame, p.len())?;
    if v.len() != p.len() {
        return Err(Error::invalid(
            "v",
            format!("expected {} directions, got {}", p.len(), v.len()),
        ));
    }
    for (x, d) in p.iter().zip(v) {
        ensure_finite("p", x.as_slice())?;
        check_unit("v", d)?;
    }
    Ok(p.par_iter()
        .zip(v.par_iter())
        .zip(frame.par_iter())
        .map_init(Vec::new, |comps, ((x, d), &f)| match fields[f].as_ref() {
            None => f64::NAN,
            Some(field) => {
                components(field.charges(), x, comps);
                log_density_from(comps, field.kappa(), d)
            }
        })
        .collect())
}

/// Angle (radians) between `v[k]` and the direction from `p[k]` to the nearest-in-angle
/// charge of `frame[k]`'s field, ignoring charges within `self_radius` metres of `p[k]`
/// (a member does not look at a charge on their own head) and charges of magnitude 0.
/// NaN where no charge qualifies. Used to flag members who follow no social charge.
pub fn angle_to_charges(
    fields: &[Option<GazeField>],
    frame: &[usize],
    p: &[Vector3<f64>],
    v: &[Vector3<f64>],
    self_radius: f64,
) -> Result<Vec<f64>> {
    if !(self_radius.is_finite() && self_radius >= 0.0) {
        return Err(Error::invalid("self_radius", "must be finite and >= 0"));
    }
    check_frames(fields, frame, p.len())?;
    if v.len() != p.len() {
        return Err(Error::invalid(
            "v",
            format!("expected {} directions, got {}", p.len(), v.len()),
        ));
    }
    for (x, d) in p.iter().zip(v) {
        ensure_finite("p", x.as_slice())?;
        check_unit("v", d)?;
    }
    Ok(p.par_iter()
        .zip(v.par_iter())
        .zip(frame.par_iter())
        .map(|((x, d), &f)| {
            let Some(field) = fields[f].as_ref() else {
                return f64::NAN;
            };
            let mut best = f64::NAN;
            for c in field.charges() {
                let w = c.position - x;
                let n = w.norm();
                if c.magnitude <= 0.0 || n <= self_radius || n == 0.0 {
                    continue;
                }
                let a = (w.dot(d) / n).clamp(-1.0, 1.0).acos();
                if best.is_nan() || a < best {
                    best = a;
                }
            }
            best
        })
        .collect())
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use crate::gazefield::SocialCharge;

    #[test]
    fn batch_matches_single_calls_and_gaps_are_nan() {
        let f0 = GazeField::new(vec![SocialCharge::new(Vector3::zeros(), 1.0)], 10.0).unwrap();
        let f1 = GazeField::new(
            vec![
                SocialCharge::new(Vector3::new(3.0, 0.0, 0.0), 2.0),
                SocialCharge::new(Vector3::new(0.0, 3.0, 0.0), 1.0),
            ],
            5.0,
        )
        .unwrap();
        let fields = vec![Some(f0.clone()), None, Some(f1.clone())];
        let pts = vec![
            Vector3::new(1.0, 1.0, 1.0),
            Vector3::new(1.0, 1.0, 1.0),
            Vector3::new(2.0, 1.0, 0.0),
        ];
        let fr = vec![0, 1, 2];
        let out = predict(&fields, &fr, &pts).unwrap();
        assert_eq!(out[0], f0.most_likely_direction(&pts[0]).unwrap());
        assert!(out[1].is_none());
        assert_eq!(out[2], f1.most_likely_direction(&pts[2]).unwrap());
        let v = vec![Vector3::x(), Vector3::y(), Vector3::x()];
        let ld = log_density(&fields, &fr, &pts, &v).unwrap();
        assert_eq!(ld[0], f0.log_density(&pts[0], &v[0]).unwrap());
        assert!(ld[1].is_nan());
        let ang = angle_to_charges(&fields, &fr, &pts, &v, 0.1).unwrap();
        assert!((ang[2] - std::f64::consts::FRAC_PI_4).abs() < 1e-12);
        // A charge within the self radius is ignored.
        let near = angle_to_charges(
            &fields,
            &[0],
            &[Vector3::new(0.05, 0.0, 0.0)],
            &[Vector3::x()],
            0.1,
        )
        .unwrap();
        assert!(near[0].is_nan());
        assert!(predict(&fields, &[3], &pts[..1]).is_err());
        assert!(predict(&fields, &[0], &[Vector3::new(f64::NAN, 0.0, 0.0)]).is_err());
    }
}
