//! A Rust panic caught and turned into its message, for `errors::guard`.
//!
//! Plain `std`, no pyo3: the integration tests (`tests/it/main.rs`) compile this file too and
//! run its test there. The extension module has no unit-test binary of its own (`test = false`
//! in its manifest): that binary compiled the whole module once more for this one test.

use std::any::Any;
use std::panic::{AssertUnwindSafe, catch_unwind};

/// `f()`, or the message of the panic it raised.
pub(crate) fn catch<R>(f: impl FnOnce() -> R) -> Result<R, String> {
    catch_unwind(AssertUnwindSafe(f)).map_err(|payload| panic_message(&*payload))
}

/// The message of a panic's payload.
fn panic_message(payload: &(dyn Any + Send)) -> String {
    if let Some(s) = payload.downcast_ref::<&str>() {
        (*s).to_string()
    } else if let Some(s) = payload.downcast_ref::<String>() {
        s.clone()
    } else {
        "a panic without a message".to_string()
    }
}

#[cfg(test)]
mod tests {
    use super::catch;

    #[test]
    fn catch_returns_the_value_or_the_panic_message() {
        assert_eq!(catch(|| 7), Ok(7));
        let v: Vec<u32> = Vec::new();
        let index = v.len() + 3;
        let err = catch(|| v[index]).expect_err("an out-of-bounds index panics");
        assert!(err.contains("index out of bounds"), "{err}");
        assert_eq!(
            catch(|| -> u8 { panic!("{} went wrong", "something") }),
            Err("something went wrong".to_string())
        );
        assert_eq!(
            catch(|| -> u8 { std::panic::panic_any(42_u32) }),
            Err("a panic without a message".to_string())
        );
    }
}
