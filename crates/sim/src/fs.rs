//! Writing files so that a crash never leaves half of one: every crate's files (policies,
//! checkpoints, run directories, generated maps, reports) go through [`write_atomic`].

use std::io::Write as _;
use std::path::Path;

/// Write `bytes` to `path` through a temporary file in the same directory, fsync and a rename,
/// so a crash never leaves a half-written file under the final name. The directory is created
/// if missing; the file gets 0o666 less the umask, as `File::create` gives.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    std::fs::create_dir_all(dir)?;
    // tempfile's own default is 0o600.
    let mode = <std::fs::Permissions as std::os::unix::fs::PermissionsExt>::from_mode(0o666);
    let mut file = tempfile::Builder::new().permissions(mode).tempfile_in(dir)?;
    // Through the plain file: NamedTempFile's own writes name the temporary path in errors.
    file.as_file_mut().write_all(bytes)?;
    file.as_file().sync_all()?;
    file.persist(path).map_err(|e| e.error)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::os::unix::fs::PermissionsExt as _;

    /// The file lands whole under its name, in a directory made for it, with the mode
    /// `File::create` gives; a second write replaces it; no temporary file stays behind.
    #[test]
    fn write_atomic_replaces_the_file_whole_and_leaves_nothing_else() {
        let d = tempfile::tempdir().unwrap();
        let path = d.path().join("new/dir/report.json");
        write_atomic(&path, b"first").unwrap();
        write_atomic(&path, b"second, longer").unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), b"second, longer");
        let plain = d.path().join("plain");
        std::fs::File::create(&plain).unwrap();
        let mode = |p: &Path| std::fs::metadata(p).unwrap().permissions().mode() & 0o777;
        assert_eq!(mode(&path), mode(&plain));
        let names: Vec<_> = std::fs::read_dir(path.parent().unwrap())
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(names, ["report.json"]);
    }
}
