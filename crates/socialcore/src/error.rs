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
