//! Calls into third-party decoders that can panic on damaged input, turned into errors.
//!
//! Two decoders olmap uses panic on some damaged files no check beforehand can foresee: the
//! LASzip decoder of the `laz` crate (an assertion in its arithmetic decoder, an index out
//! of range on a corrupt chunk table) and the `mcap` reader (arithmetic on a damaged length
//! that overflows where overflow is checked). olmap runs those calls through `guarded`
//! (crate-private), which catches the panic and hands its message to the caller, who
//! reports the file as damaged with a typed error. The panic hook still runs when the panic happens; a program
//! that reports errors itself installs [`quiet_guarded_panics`] once, so that a damaged
//! file prints its error and nothing else (the `olmap` command and the Python module do).

use std::cell::Cell;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::Once;

thread_local! {
    /// How many [`guarded`] calls this thread is inside.
    static DEPTH: Cell<u32> = const { Cell::new(0) };
}

/// Runs `call`; a panic inside it becomes `Err(its message)`. Only for calls into a
/// decoder whose state is dropped afterwards (nothing it touched is used again). The quiet
/// hook knows the call by this thread only: a panic on a thread the call started would
/// still be printed (neither guarded decoder starts threads: `laz` is built without its
/// `parallel` feature, the MCAP reader and its decompressors run on the caller's thread).
#[cfg_attr(not(any(feature = "las", feature = "bag")), allow(dead_code))]
pub(crate) fn guarded<T>(call: impl FnOnce() -> T) -> Result<T, String> {
    DEPTH.with(|d| d.set(d.get() + 1));
    let result = catch_unwind(AssertUnwindSafe(call));
    DEPTH.with(|d| d.set(d.get() - 1));
    result.map_err(|payload| {
        payload
            .downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| payload.downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "a panic without a message".into())
    })
}

/// Installs, once per process, a panic hook that prints nothing for a panic `guarded`
/// catches (its caller reports the damaged file) and passes every other panic to the hook
/// installed before it (by default: the message on stderr).
///
/// ```
/// olmap::guard::quiet_guarded_panics();
/// // Reading a damaged LAZ file now prints only olmap's error about it.
/// ```
pub fn quiet_guarded_panics() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        let previous = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            if DEPTH.with(Cell::get) == 0 {
                previous(info);
            }
        }));
    });
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_panic_becomes_its_message_and_the_depth_is_restored() {
        quiet_guarded_panics();
        let r: Result<(), String> = guarded(|| panic!("damaged: {}", 7));
        assert_eq!(r.unwrap_err(), "damaged: 7");
        assert_eq!(guarded(|| 5).unwrap(), 5);
        assert_eq!(DEPTH.with(Cell::get), 0);
    }
}
