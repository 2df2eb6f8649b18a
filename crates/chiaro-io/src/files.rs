//! Opening the files a scene names (and the scene file itself): the one
//! place every loader reads a whole file through.
//!
//! A scene is untrusted input, and so is every path in it (`mtllib`,
//! `map_Kd`, a glTF buffer or image URI, a TOML `file` or `texture`).
//! [`read_file`] reads only regular files (a device such as `/dev/zero`
//! never ends, a FIFO blocks forever), checks the file's size against the
//! memory budget before reading anything, and reads no more than that size
//! (a file that grows while it is read is refused, not followed). Relative
//! paths that climb out of the scene's folder stay allowed: Mitsuba's test
//! scenes name `../../../common`.

use crate::{IoError, Result};
use chiaro_core::budget::{ByteSize, MemoryBudget};
use std::fs::{File, Metadata};
use std::io::Read;
use std::path::Path;

/// What a path that is not a regular file is, in words (`None` for a
/// regular file).
fn not_regular(meta: &Metadata) -> Option<&'static str> {
    let t = meta.file_type();
    if t.is_file() {
        return None;
    }
    if t.is_dir() {
        return Some("a directory");
    }
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        if t.is_fifo() {
            return Some("a FIFO (named pipe)");
        }
        if t.is_socket() {
            return Some("a socket");
        }
        if t.is_char_device() {
            return Some("a character device");
        }
        if t.is_block_device() {
            return Some("a block device");
        }
    }
    Some("not a regular file")
}

/// The refusal of a path that exists but is not a regular file, or `None`
/// when `path` is a regular file or does not exist (the caller reports
/// that in its own words).
pub fn refuse_special(path: &Path) -> Option<IoError> {
    let meta = std::fs::metadata(path).ok()?;
    not_regular(&meta).map(|kind| special_error(path, kind))
}

fn special_error(path: &Path, kind: &str) -> IoError {
    IoError::format(
        path,
        format!(
            "{kind}, not a regular file: chiaro reads scenes, meshes and images only from regular files"
        ),
    )
}

/// Reads the whole file at `path` within the process memory budget
/// ([`MemoryBudget::process`], the CLI's `--memory-limit`).
///
/// # Errors
/// As [`read_file_within`].
pub fn read_file(path: &Path) -> Result<Vec<u8>> {
    read_file_within(path, MemoryBudget::process(), u64::MAX)
}

/// Reads the whole file at `path`, refusing it before reading when it is
/// not a regular file, or when its size exceeds `max_bytes` or `budget`.
/// Returns its bytes.
///
/// # Errors
/// [`IoError::Io`] when the file cannot be opened or read;
/// [`IoError::Format`] naming the file when it is a directory, device,
/// FIFO or socket, is larger than `max_bytes` or the budget, or grew past
/// its size while being read.
pub fn read_file_within(path: &Path, budget: MemoryBudget, max_bytes: u64) -> Result<Vec<u8>> {
    // Look before opening: opening a FIFO for reading blocks until a
    // writer comes, and a device reads without end.
    if let Some(e) = refuse_special(path) {
        return Err(e);
    }
    let mut file = File::open(path).map_err(|e| IoError::io(path, e))?;
    // Check again what was opened (the path may have changed in between).
    let meta = file.metadata().map_err(|e| IoError::io(path, e))?;
    if let Some(kind) = not_regular(&meta) {
        return Err(special_error(path, kind));
    }
    let len = meta.len();
    if len > max_bytes {
        return Err(IoError::format(
            path,
            format!(
                "the file is {}, larger than the {} chiaro reads of this kind",
                ByteSize(len),
                ByteSize(max_bytes)
            ),
        ));
    }
    budget
        .check("reading the file", len)
        .map_err(|m| IoError::format(path, m))?;
    // Read one byte past the size to see a file that grew meanwhile.
    let mut bytes = Vec::with_capacity(usize::try_from(len).unwrap_or(0));
    (&mut file)
        .take(len.saturating_add(1))
        .read_to_end(&mut bytes)
        .map_err(|e| IoError::io(path, e))?;
    if bytes.len() as u64 > len {
        return Err(IoError::format(
            path,
            format!(
                "the file grew past its size of {} while it was read",
                ByteSize(len)
            ),
        ));
    }
    Ok(bytes)
}

/// [`read_file`] for a text file: its bytes as UTF-8.
///
/// # Errors
/// As [`read_file`], and [`IoError::At`] at the first byte that is not
/// UTF-8.
pub fn read_text_file(path: &Path) -> Result<String> {
    let bytes = read_file(path)?;
    String::from_utf8(bytes).map_err(|e| {
        let valid = e.utf8_error().valid_up_to();
        let before = String::from_utf8_lossy(&e.as_bytes()[..valid]).into_owned();
        let (line, column) = crate::scene_toml::line_col(&before, before.len());
        IoError::At {
            path: path.to_path_buf(),
            line,
            column,
            message: "the text is not UTF-8".into(),
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn devices_and_directories_are_refused_by_kind() {
        let msg = read_file(Path::new("/dev/zero"))
            .expect_err("device")
            .to_string();
        assert!(
            msg.contains("/dev/zero") && msg.contains("character device"),
            "{msg}"
        );
        let msg = read_file(Path::new("/")).expect_err("dir").to_string();
        assert!(msg.contains("a directory"), "{msg}");
    }

    #[test]
    fn size_is_checked_before_reading() {
        let dir = std::env::temp_dir().join(format!("chiaro-files-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("dir");
        let path = dir.join("ten.bin");
        std::fs::write(&path, [7u8; 10]).expect("write");
        assert_eq!(
            read_file_within(&path, MemoryBudget::new(10), u64::MAX).expect("fits"),
            vec![7u8; 10]
        );
        let msg = read_file_within(&path, MemoryBudget::new(9), u64::MAX)
            .expect_err("over budget")
            .to_string();
        assert!(
            msg.contains("ten.bin") && msg.contains("memory limit is 9 B"),
            "{msg}"
        );
        let msg = read_file_within(&path, MemoryBudget::new(100), 4)
            .expect_err("over cap")
            .to_string();
        assert!(msg.contains("10 B, larger than the 4 B"), "{msg}");
        std::fs::write(&path, b"ok\n\xffno").expect("write");
        let msg = read_text_file(&path).expect_err("not utf-8").to_string();
        assert!(msg.contains("ten.bin:2:1: the text is not UTF-8"), "{msg}");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
