//! Resuming the pose stage. COLMAP 3.8 skips an image whose keypoints and
//! descriptors are already in the database ("SKIP: Features for image already
//! extracted.") and an image pair whose matches are already there, and it
//! commits both as it goes, so a database kept from an interrupted run holds
//! the work done so far. That is only right while the database was built from
//! the same inputs with the same settings; [`ResumeState`] (saved as
//! `work/resume.json`) records what the database holds:
//!
//! - features: the image list (name, size, mtime), the masks (name, size,
//!   content hash — the mask stage may rewrite identical masks) and every
//!   option that changes keypoints; a difference starts a fresh database;
//! - matching: matcher, overlap and loop detection; a difference clears the
//!   matches (`colmap database_cleaner --type matches`) and keeps the features.

use crate::error::{PoseError, Result};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// One input file as the resume check sees it.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct FileKey {
    pub name: String,
    pub size: u64,
    /// Modification time in nanoseconds since the epoch (images), or 0.
    pub mtime_ns: u128,
    /// FNV-1a 64 of the content (masks), or 0.
    pub hash: u64,
}

/// Everything the extracted features depend on.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct FeatureKey {
    /// `colmap -h` version line.
    pub colmap_version: String,
    pub images: Vec<FileKey>,
    /// Empty without masks.
    pub masks: Vec<FileKey>,
    /// Camera model, single camera, max image size, max features, seed: as text.
    pub settings: Vec<(String, String)>,
}

/// Everything the matches depend on (besides the features).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct MatchKey {
    pub settings: Vec<(String, String)>,
}

/// What the kept database holds.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct ResumeState {
    pub features: FeatureKey,
    /// `None` until matching was started with these features.
    pub matching: Option<MatchKey>,
}

/// FNV-1a, 64 bit.
pub fn fnv1a64(bytes: &[u8]) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for &b in bytes {
        h ^= u64::from(b);
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    h
}

/// Size and mtime of `dir/name`.
pub fn file_key_stat(dir: &Path, name: &str) -> Result<FileKey> {
    let p = dir.join(name);
    let meta = std::fs::metadata(&p).map_err(|e| PoseError::io(&p, e))?;
    let mtime_ns = meta
        .modified()
        .ok()
        .and_then(|t| t.duration_since(std::time::UNIX_EPOCH).ok())
        .map_or(0, |d| d.as_nanos());
    Ok(FileKey {
        name: name.to_string(),
        size: meta.len(),
        mtime_ns,
        hash: 0,
    })
}

/// Size and content hash of `dir/name`.
pub fn file_key_hash(dir: &Path, name: &str) -> Result<FileKey> {
    let p = dir.join(name);
    let bytes = std::fs::read(&p).map_err(|e| PoseError::io(&p, e))?;
    Ok(FileKey {
        name: name.to_string(),
        size: bytes.len() as u64,
        mtime_ns: 0,
        hash: fnv1a64(&bytes),
    })
}

/// Read `work/resume.json`; `None` when absent or unreadable (a fresh start).
pub fn load(path: &Path) -> Option<ResumeState> {
    let text = std::fs::read_to_string(path).ok()?;
    serde_json::from_str(&text).ok()
}

/// Write `work/resume.json` atomically.
pub fn save(path: &Path, state: &ResumeState) -> Result<()> {
    let text = serde_json::to_string_pretty(state)
        .map_err(|e| PoseError::Invalid(format!("{}: {e}", path.display())))?;
    loader::io::write_atomic(path, |w| {
        w.write_all(text.as_bytes())
            .map_err(|e| loader::LoaderError::io(path, e))
    })?;
    Ok(())
}

/// What to do with a kept database.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Decision {
    /// No usable database: start a fresh one.
    Fresh,
    /// Keep the features, clear the matches (matching settings changed).
    KeepFeatures,
    /// Keep features and matches; COLMAP skips what is done.
    KeepAll,
}

/// Decide from the saved state and the current keys.
pub fn decide(
    saved: Option<&ResumeState>,
    db_exists: bool,
    features: &FeatureKey,
    matching: &MatchKey,
) -> Decision {
    match saved {
        Some(s) if db_exists && s.features == *features => match &s.matching {
            Some(m) if m != matching => Decision::KeepFeatures,
            _ => Decision::KeepAll,
        },
        _ => Decision::Fresh,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn key(images: &[(&str, u64)]) -> FeatureKey {
        FeatureKey {
            colmap_version: "COLMAP 3.8".into(),
            images: images
                .iter()
                .map(|(n, s)| FileKey {
                    name: (*n).into(),
                    size: *s,
                    mtime_ns: 1,
                    hash: 0,
                })
                .collect(),
            masks: Vec::new(),
            settings: vec![("max_image_size".into(), "1000".into())],
        }
    }

    fn mk(overlap: u32) -> MatchKey {
        MatchKey {
            settings: vec![("overlap".into(), overlap.to_string())],
        }
    }

    #[test]
    fn decisions() {
        let f = key(&[("a.png", 10), ("b.png", 12)]);
        let s = ResumeState {
            features: f.clone(),
            matching: Some(mk(5)),
        };
        assert_eq!(decide(Some(&s), true, &f, &mk(5)), Decision::KeepAll);
        assert_eq!(decide(Some(&s), true, &f, &mk(6)), Decision::KeepFeatures);
        assert_eq!(decide(Some(&s), false, &f, &mk(5)), Decision::Fresh);
        assert_eq!(decide(None, true, &f, &mk(5)), Decision::Fresh);
        let g = key(&[("a.png", 10), ("b.png", 13)]);
        assert_eq!(decide(Some(&s), true, &g, &mk(5)), Decision::Fresh);
        let unmatched = ResumeState {
            features: f.clone(),
            matching: None,
        };
        assert_eq!(
            decide(Some(&unmatched), true, &f, &mk(9)),
            Decision::KeepAll
        );
    }

    #[test]
    fn state_round_trips_and_hash_sees_content() {
        let d = tempfile::tempdir().unwrap();
        let s = ResumeState {
            features: key(&[("a.png", 10)]),
            matching: Some(mk(3)),
        };
        let p = d.path().join("resume.json");
        save(&p, &s).unwrap();
        assert_eq!(load(&p), Some(s));
        std::fs::write(d.path().join("m.png"), b"abc").unwrap();
        let k1 = file_key_hash(d.path(), "m.png").unwrap();
        std::fs::write(d.path().join("m.png"), b"abd").unwrap();
        let k2 = file_key_hash(d.path(), "m.png").unwrap();
        assert_ne!(k1, k2);
        std::fs::write(d.path().join("m.png"), b"abc").unwrap();
        assert_eq!(file_key_hash(d.path(), "m.png").unwrap(), k1);
        // Known FNV-1a 64 values.
        assert_eq!(fnv1a64(b""), 0xcbf2_9ce4_8422_2325);
        assert_eq!(fnv1a64(b"a"), 0xaf63_dc4c_8601_ec8c);
    }
}
