//! Ctrl-C and SIGTERM as a flag the long-running commands look at.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, OnceLock};

/// Set when the user presses Ctrl-C (SIGINT) or the process gets SIGTERM: long-running
/// commands stop at the next frame, flush their output and exit 0, as can-utils do.
pub fn interrupt_flag() -> Arc<AtomicBool> {
    static FLAG: OnceLock<Arc<AtomicBool>> = OnceLock::new();
    Arc::clone(FLAG.get_or_init(|| {
        let flag = Arc::new(AtomicBool::new(false));
        let set = Arc::clone(&flag);
        // Without a handler (e.g. one is already installed) Ctrl-C simply ends the process.
        let _ = ctrlc::set_handler(move || set.store(true, Ordering::Relaxed));
        flag
    }))
}
