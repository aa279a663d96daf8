//! Cooperative cancellation of long core calls (Ctrl-C from Python).
//!
//! The core never looks at signals itself. A caller (the Python binding) raises the
//! process-wide flag with [`request`] when the user interrupts; every long-running loop of
//! the core calls [`check`] at a coarse grain (per frame chunk, per branch-and-bound node
//! batch, per EM iteration) and returns [`Error::Interrupted`] as soon as the flag is set.
//! The caller clears the flag with [`clear`] once the interrupted call has returned.
//!
//! The flag is process-wide, not per call: an interrupt stops every core call running at
//! that moment, which is what Ctrl-C means for an interactive session.

use crate::{Error, Result};
use std::sync::atomic::{AtomicBool, Ordering};

static REQUESTED: AtomicBool = AtomicBool::new(false);

/// Asks every running core call to stop at its next check.
pub fn request() {
    REQUESTED.store(true, Ordering::SeqCst);
}

/// Clears a request made with [`request`].
pub fn clear() {
    REQUESTED.store(false, Ordering::SeqCst);
}

/// Whether a stop has been requested (one relaxed atomic load: cheap enough for hot loops).
#[inline]
pub fn requested() -> bool {
    REQUESTED.load(Ordering::Relaxed)
}

/// `Err(Error::Interrupted)` when a stop has been requested, `Ok(())` otherwise.
#[inline]
pub fn check() -> Result<()> {
    if requested() {
        Err(Error::Interrupted)
    } else {
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn request_then_clear() {
        // The flag is global: this test is the only one in the crate that sets it.
        assert!(check().is_ok());
        request();
        assert_eq!(check(), Err(Error::Interrupted));
        clear();
        assert!(check().is_ok());
    }
}
