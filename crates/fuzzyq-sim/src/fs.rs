//! Reading input files within bounds: configurations, arenas, policy files and transitions
//! are read once (a pipe or a FIFO works) and never beyond a cap, so that `/dev/zero` or an
//! endless pipe ends in a clear error rather than with the memory exhausted.

use std::io::Read;
use std::path::Path;

/// The most fuzzyq reads of a text file (a configuration, an arena, a policy learned from
/// samples in the old TOML form): 16 MiB, far beyond any real one.
pub const MAX_TEXT_BYTES: u64 = 16 << 20;

/// The most fuzzyq reads of a transitions CSV: 4 GiB (about 20 million transitions of the
/// point masses).
pub const MAX_TRANSITIONS_BYTES: u64 = 4 << 30;

/// Reads `reader` to its end, refusing more than `cap` bytes (an error of kind `InvalidData`
/// naming the cap), so that `/dev/zero` or an endless pipe ends with an error, not with the
/// memory exhausted.
pub fn read_capped(reader: impl Read, cap: u64) -> std::io::Result<Vec<u8>> {
    let mut out = Vec::new();
    reader.take(cap.saturating_add(1)).read_to_end(&mut out)?;
    if out.len() as u64 > cap {
        return Err(too_long(cap));
    }
    Ok(out)
}

/// How long [`open`] waits for a process to open a FIFO for writing.
pub const FIFO_WAIT: std::time::Duration = std::time::Duration::from_secs(10);

/// Opens the input file at `path` for reading. A FIFO (named pipe) is opened without blocking
/// and given [`FIFO_WAIT`] for a writer to appear, so that a FIFO nobody writes to ends in an
/// error instead of waiting forever; other files open as usual.
pub fn open(path: &Path) -> std::io::Result<std::fs::File> {
    #[cfg(unix)]
    {
        use rustix::event::{PollFd, PollFlags, Timespec};
        use rustix::fs::OFlags;
        use std::os::unix::fs::{FileTypeExt, OpenOptionsExt};
        if std::fs::metadata(path)?.file_type().is_fifo() {
            let file = std::fs::OpenOptions::new()
                .read(true)
                .custom_flags(OFlags::NONBLOCK.bits() as i32)
                .open(path)?;
            // A FIFO with no writer since it was opened reports no event (not even a hang-up)
            // until one opens it: wait for that, or give up.
            let mut fds = [PollFd::new(&file, PollFlags::IN)];
            let wait = Timespec {
                tv_sec: FIFO_WAIT.as_secs() as _,
                tv_nsec: 0,
            };
            if rustix::event::poll(&mut fds, Some(&wait))? == 0 {
                return Err(std::io::Error::new(
                    std::io::ErrorKind::TimedOut,
                    format!(
                        "a FIFO that no process opened for writing within {} s",
                        FIFO_WAIT.as_secs()
                    ),
                ));
            }
            // Blocking reads from here on: the writer is there.
            let flags = rustix::fs::fcntl_getfl(&file)?;
            rustix::fs::fcntl_setfl(&file, flags - OFlags::NONBLOCK)?;
            return Ok(file);
        }
    }
    std::fs::File::open(path)
}

/// The longest line fuzzyq reads in a text file: 1 MiB.
pub const MAX_LINE_BYTES: u64 = 1 << 20;

/// The text of the file at `path`, read once (a pipe or a FIFO works), at most `cap` bytes and
/// lines of at most [`MAX_LINE_BYTES`]: binary data such as `/dev/zero` is refused after its
/// first megabyte.
pub fn read_text(path: &Path, cap: u64) -> std::io::Result<String> {
    use std::io::BufRead;
    let mut reader = std::io::BufReader::new(open(path)?);
    let mut out = Vec::new();
    for line in 1.. {
        let n = (&mut reader)
            .take(MAX_LINE_BYTES + 1)
            .read_until(b'\n', &mut out)?;
        if n == 0 {
            break;
        }
        if n as u64 > MAX_LINE_BYTES {
            return Err(invalid(format!(
                "line {line} is longer than {}: not a text file fuzzyq reads",
                bytes_text(MAX_LINE_BYTES)
            )));
        }
        if out.len() as u64 > cap {
            return Err(too_long(cap));
        }
    }
    String::from_utf8(out).map_err(|e| {
        invalid(format!(
            "not UTF-8 text (byte {})",
            e.utf8_error().valid_up_to()
        ))
    })
}

fn invalid(message: String) -> std::io::Error {
    std::io::Error::new(std::io::ErrorKind::InvalidData, message)
}

/// The error of a file longer than `cap` bytes.
fn too_long(cap: u64) -> std::io::Error {
    invalid(format!(
        "longer than {}, the most fuzzyq reads of such a file",
        bytes_text(cap)
    ))
}

/// `bytes` as `16 MiB`, `4 GiB`.
fn bytes_text(bytes: u64) -> String {
    match bytes {
        b if b >= 1 << 30 => format!("{} GiB", b >> 30),
        b if b >= 1 << 20 => format!("{} MiB", b >> 20),
        b => format!("{b} bytes"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_within_the_caps_and_refuses_beyond() {
        assert_eq!(read_capped(&b"abc"[..], 3).unwrap(), b"abc");
        let e = read_capped(&b"abcd"[..], 3).unwrap_err().to_string();
        assert!(e.contains("longer than 3 bytes"), "{e}");
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("t.toml");
        std::fs::write(&p, "a = 1\nb = 2\n").unwrap();
        assert_eq!(read_text(&p, 100).unwrap(), "a = 1\nb = 2\n");
        assert!(
            read_text(&p, 8)
                .unwrap_err()
                .to_string()
                .contains("longer than 8 bytes")
        );
        std::fs::write(&p, [b'x'; (MAX_LINE_BYTES + 1) as usize]).unwrap();
        let e = read_text(&p, MAX_TEXT_BYTES).unwrap_err().to_string();
        assert_eq!(
            e,
            "line 1 is longer than 1 MiB: not a text file fuzzyq reads"
        );
        std::fs::write(&p, b"ok\n\xff\n").unwrap();
        let e = read_text(&p, 100).unwrap_err().to_string();
        assert_eq!(e, "not UTF-8 text (byte 3)");
    }
}
