//! The one error type of the core. The binding maps each kind to a Python exception
//! (`InvalidInput` → `ValueError`, `Degenerate` → `socialcam.DegenerateError`).

/// Everything the core can refuse or fail at. The core never panics on user input.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum Error {
    /// The caller passed something malformed: a wrong shape, a NaN, a non-rotation.
    #[error("{arg}: {msg}")]
    InvalidInput { arg: String, msg: String },
    /// The data are well formed but make the problem geometrically degenerate
    /// (rank deficiency, parallel rays, too few observations).
    #[error("{0}")]
    Degenerate(String),
    /// An iterative method reached its cap without meeting its tolerance.
    #[error("did not converge after {iterations} iterations")]
    NotConverged { iterations: usize },
    /// The caller asked the computation to stop ([`crate::interrupt::request`]).
    #[error("interrupted")]
    Interrupted,
}

impl Error {
    /// Shorthand for [`Error::InvalidInput`].
    pub fn invalid(arg: impl Into<String>, msg: impl Into<String>) -> Self {
        Error::InvalidInput {
            arg: arg.into(),
            msg: msg.into(),
        }
    }
    /// Shorthand for [`Error::Degenerate`].
    pub fn degenerate(msg: impl Into<String>) -> Self {
        Error::Degenerate(msg.into())
    }
}

/// Result alias used across the core.
pub type Result<T> = std::result::Result<T, Error>;

/// Fails with `InvalidInput` unless every value is finite.
pub fn ensure_finite(arg: &str, values: &[f64]) -> Result<()> {
    if let Some(i) = values.iter().position(|v| !v.is_finite()) {
        return Err(Error::invalid(
            arg,
            format!("contains a non-finite value at flat index {i}"),
        ));
    }
    Ok(())
}

/// The largest single allocation (bytes) the core makes on behalf of a user-given size.
/// Anything larger is refused with `InvalidInput` naming the argument, instead of letting
/// the allocator abort the process.
pub const MAX_ALLOC_BYTES: usize = 2 << 30;

/// Fails with `InvalidInput` naming `arg` when an array of `dims` elements of
/// `elem_bytes` bytes each would exceed [`MAX_ALLOC_BYTES`] (or overflow `usize`).
pub fn ensure_alloc(arg: &str, dims: &[usize], elem_bytes: usize) -> Result<()> {
    let total = dims
        .iter()
        .try_fold(elem_bytes, |acc, &d| acc.checked_mul(d));
    match total {
        Some(b) if b <= MAX_ALLOC_BYTES => Ok(()),
        _ => {
            let shape: Vec<String> = dims.iter().map(|d| d.to_string()).collect();
            Err(Error::invalid(
                arg,
                format!(
                    "too large: an array of shape ({}) would need more than {} GiB",
                    shape.join(", "),
                    MAX_ALLOC_BYTES >> 30
                ),
            ))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn alloc_limit_names_the_argument() {
        assert!(ensure_alloc("k", &[10, 10], 8).is_ok());
        let e = ensure_alloc("k", &[1000, 1_000_000_000], 8).unwrap_err();
        assert!(e.to_string().starts_with("k: too large"), "{e}");
        // Overflow of the product is refused too, not wrapped.
        assert!(ensure_alloc("k", &[usize::MAX, 3], 8).is_err());
    }
}
