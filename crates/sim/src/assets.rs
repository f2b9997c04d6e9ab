//! Where model and scene files come from: a directory on disk, or the copies embedded at build
//! time (`assets/` of the workspace). Paths are relative, with `/` separators.

use crate::SimError;
use std::path::{Path, PathBuf};

mod embedded {
    include!(concat!(env!("OUT_DIR"), "/assets.rs"));
}

/// A tree of asset files.
#[derive(Clone, Debug, Default)]
pub enum AssetSource {
    /// The files embedded in the binary at build time.
    #[default]
    Embedded,
    /// A directory on disk (relative paths resolve against it).
    Dir(PathBuf),
}

impl AssetSource {
    /// The source for built-in assets: `$AGVRL_ASSETS` when set, else the embedded copies.
    pub fn builtin() -> Self {
        match std::env::var_os("AGVRL_ASSETS") {
            Some(dir) => AssetSource::Dir(PathBuf::from(dir)),
            None => AssetSource::Embedded,
        }
    }

    /// A file on disk as (its directory, its name), so files it names resolve beside it.
    pub fn for_file(path: &Path) -> (Self, String) {
        let dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
        let name = path
            .file_name()
            .and_then(|n| n.to_str())
            .unwrap_or_default()
            .to_string();
        (AssetSource::Dir(dir), name)
    }

    /// Read `rel` (e.g. `vehicles/xtenth_car.urdf`) as text.
    pub fn read(&self, rel: &str) -> Result<String, SimError> {
        match self {
            AssetSource::Embedded => embedded::EMBEDDED
                .iter()
                .find(|(p, _)| *p == rel)
                .map(|(_, s)| s.to_string())
                .ok_or_else(|| SimError::Io {
                    path: PathBuf::from(rel),
                    source: std::io::Error::new(std::io::ErrorKind::NotFound, "no such built-in asset"),
                }),
            AssetSource::Dir(dir) => {
                let path = dir.join(rel);
                std::fs::read_to_string(&path).map_err(|source| SimError::Io { path, source })
            }
        }
    }

    /// Names (file stems) of the files under `dir` with extension `ext`, sorted.
    pub fn list(&self, dir: &str, ext: &str) -> Vec<String> {
        let mut out: Vec<String> = match self {
            AssetSource::Embedded => embedded::EMBEDDED
                .iter()
                .filter_map(|(p, _)| {
                    let rest = p.strip_prefix(dir)?.strip_prefix('/')?;
                    (!rest.contains('/'))
                        .then_some(rest)?
                        .strip_suffix(&format!(".{ext}"))
                        .map(str::to_string)
                })
                .collect(),
            AssetSource::Dir(root) => std::fs::read_dir(root.join(dir))
                .map(|rd| {
                    rd.filter_map(Result::ok)
                        .filter_map(|e| {
                            let p = e.path();
                            (p.extension()? == ext).then(|| p.file_stem()?.to_str().map(str::to_string))?
                        })
                        .collect()
                })
                .unwrap_or_default(),
        };
        out.sort();
        out
    }

    /// A human-readable location for `rel`, for error messages.
    pub fn display_path(&self, rel: &str) -> PathBuf {
        match self {
            AssetSource::Embedded => Path::new("<built-in>/assets").join(rel),
            AssetSource::Dir(dir) => dir.join(rel),
        }
    }
}

/// The embedded asset files as (path relative to `assets/`, contents).
pub(crate) fn embedded_files() -> &'static [(&'static str, &'static str)] {
    embedded::EMBEDDED
}

/// Resolve `rel` relative to the directory of `base` (both asset-relative, `/`-separated).
pub fn join_rel(base: &str, rel: &str) -> String {
    match base.rfind('/') {
        Some(i) => format!("{}/{}", &base[..i], rel),
        None => rel.to_string(),
    }
}
