//! split.json in the NeRF On-the-go form (Ren et al., CVPR 2024):
//! `{"clutter": [...], "extra": [...], "clean": [...]}` where `clutter` are
//! the training frames (with distractors), `extra` the clean held-out test
//! views and the optional `clean` clean training frames. Entries are image
//! indices (into the scene's sorted image list) or image names.

use crate::error::{LoaderError, Result};
use crate::io::{read_string, write_atomic};
use serde::{Deserialize, Serialize};
use std::io::Write;
use std::path::Path;

/// One entry: an index into the sorted image list or an image name.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum SplitEntry {
    Index(usize),
    Name(String),
}

/// The split as written in the file.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Split {
    /// Training frames (may contain distractors).
    #[serde(default)]
    pub clutter: Vec<SplitEntry>,
    /// Held-out clean test views.
    #[serde(default)]
    pub extra: Vec<SplitEntry>,
    /// Optional clean training frames.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub clean: Option<Vec<SplitEntry>>,
}

/// A split resolved to indices into the scene's sorted image list.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct ResolvedSplit {
    pub clutter: Vec<usize>,
    pub extra: Vec<usize>,
    pub clean: Option<Vec<usize>>,
}

impl ResolvedSplit {
    /// Indices of a split by its name (`clutter`/`train`, `extra`/`test`, `clean`).
    pub fn get(&self, which: &str) -> Option<&[usize]> {
        match which {
            "clutter" | "train" => Some(&self.clutter),
            "extra" | "test" => Some(&self.extra),
            "clean" => self.clean.as_deref(),
            _ => None,
        }
    }
}

/// Read split.json. Entries must be non-negative integers (indices) or
/// strings (names); errors say which list and entry, in our words.
pub fn read_split(path: impl AsRef<Path>) -> Result<Split> {
    let path = path.as_ref();
    let text = read_string(path)?;
    parse_split(&text, path)
}

/// Parse split.json text; `path` names it in errors.
pub fn parse_split(text: &str, path: &Path) -> Result<Split> {
    let bad = |m: String| LoaderError::format(path, m);
    let value: serde_json::Value = serde_json::from_str(text).map_err(|e| {
        bad(format!(
            "not valid JSON (line {}, column {})",
            e.line(),
            e.column()
        ))
    })?;
    let obj = value
        .as_object()
        .ok_or_else(|| bad("expected an object with \"clutter\" and \"extra\" lists".into()))?;
    let list = |key: &str| -> Result<Option<Vec<SplitEntry>>> {
        let Some(v) = obj.get(key) else {
            return Ok(None);
        };
        let arr = v
            .as_array()
            .ok_or_else(|| bad(format!("{key}: expected a list of image indices or names")))?;
        arr.iter()
            .enumerate()
            .map(|(i, e)| match e {
                serde_json::Value::String(n) => Ok(SplitEntry::Name(n.clone())),
                serde_json::Value::Number(n) => match (n.as_u64(), n.as_i64()) {
                    (Some(u), _) => usize::try_from(u)
                        .map(SplitEntry::Index)
                        .map_err(|_| bad(format!("{key}[{i}]: index {u} out of range"))),
                    (None, Some(neg)) => Err(bad(format!(
                        "{key}[{i}]: index {neg} is negative (indices count from 0)"
                    ))),
                    _ => Err(bad(format!("{key}[{i}]: {n} is not a whole-number index"))),
                },
                other => Err(bad(format!(
                    "{key}[{i}]: {other} is neither an image index nor a name"
                ))),
            })
            .collect::<Result<Vec<_>>>()
            .map(Some)
    };
    Ok(Split {
        clutter: list("clutter")?.unwrap_or_default(),
        extra: list("extra")?.unwrap_or_default(),
        clean: list("clean")?,
    })
}

/// Write split.json atomically.
pub fn write_split(path: impl AsRef<Path>, split: &Split) -> Result<()> {
    let path = path.as_ref();
    let text = serde_json::to_string_pretty(split)
        .map_err(|e| LoaderError::format(path, e.to_string()))?;
    write_atomic(path, |w: &mut dyn Write| {
        w.write_all(text.as_bytes())
            .map_err(|e| LoaderError::io(path, e))
    })
}

impl Split {
    /// A split listing names.
    pub fn from_names(clutter: &[String], extra: &[String], clean: Option<&[String]>) -> Self {
        let f = |v: &[String]| v.iter().cloned().map(SplitEntry::Name).collect();
        Split {
            clutter: f(clutter),
            extra: f(extra),
            clean: clean.map(f),
        }
    }

    /// Resolve entries against `names` (the scene's sorted image file names).
    /// A name matches exactly or by file stem (`0001` matches `0001.jpg`).
    /// `path` names split.json in errors.
    pub fn resolve(&self, path: &Path, names: &[String]) -> Result<ResolvedSplit> {
        let one = |list: &str, e: &SplitEntry| -> Result<usize> {
            match e {
                SplitEntry::Index(i) if *i < names.len() => Ok(*i),
                SplitEntry::Index(i) => Err(LoaderError::format(
                    path,
                    format!("{list}: index {i} out of range ({} images)", names.len()),
                )),
                SplitEntry::Name(n) => names
                    .iter()
                    .position(|x| x == n)
                    .or_else(|| {
                        names
                            .iter()
                            .position(|x| Path::new(x).file_stem().is_some_and(|s| s == n.as_str()))
                    })
                    .ok_or_else(|| {
                        LoaderError::format(
                            path,
                            format!("{list}: image {n:?} is not in the scene"),
                        )
                    }),
            }
        };
        let all = |list: &str, v: &[SplitEntry]| {
            v.iter()
                .map(|e| one(list, e))
                .collect::<Result<Vec<usize>>>()
        };
        let r = ResolvedSplit {
            clutter: all("clutter", &self.clutter)?,
            extra: all("extra", &self.extra)?,
            clean: self.clean.as_ref().map(|c| all("clean", c)).transpose()?,
        };
        // Held-out views must not be trained on.
        for (list, v) in [("clutter", Some(&r.clutter)), ("clean", r.clean.as_ref())] {
            if let Some(i) = v.and_then(|v| v.iter().find(|i| r.extra.contains(i))) {
                return Err(LoaderError::format(
                    path,
                    format!(
                        "image {} ({}) is in both {list} (training) and extra (held out)",
                        i, names[*i]
                    ),
                ));
            }
        }
        Ok(r)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names() -> Vec<String> {
        ["000.jpg", "001.jpg", "002.jpg", "003.jpg"]
            .iter()
            .map(|s| s.to_string())
            .collect()
    }

    #[test]
    fn indices_and_names_resolve() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("split.json");
        std::fs::write(&p, r#"{"clutter": [0, 2], "extra": ["001.jpg", "003"]}"#).unwrap();
        let s = read_split(&p).unwrap();
        assert_eq!(s.clean, None);
        let r = s.resolve(&p, &names()).unwrap();
        assert_eq!(r.clutter, vec![0, 2]);
        assert_eq!(r.extra, vec![1, 3]);
        assert_eq!(r.get("test"), Some(&[1usize, 3][..]));
        assert_eq!(r.get("clean"), None);
    }

    #[test]
    fn write_read_round_trip_with_clean() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("split.json");
        let s = Split {
            clutter: vec![SplitEntry::Index(3)],
            extra: vec![SplitEntry::Name("a.png".into())],
            clean: Some(vec![SplitEntry::Index(0)]),
        };
        write_split(&p, &s).unwrap();
        assert_eq!(read_split(&p).unwrap(), s);
        let text = std::fs::read_to_string(&p).unwrap();
        assert!(text.contains("\"clutter\"") && text.contains("\"clean\""));
    }

    #[test]
    fn bad_entries_name_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("split.json");
        // The error of resolving `json` against `names()`.
        let resolve_err = |json: &str| {
            std::fs::write(&p, json).unwrap();
            read_split(&p)
                .unwrap()
                .resolve(&p, &names())
                .unwrap_err()
                .to_string()
        };
        let e = resolve_err(r#"{"clutter": [9], "extra": []}"#);
        assert!(
            e.contains("split.json") && e.contains("index 9 out of range"),
            "{e}"
        );
        let e = resolve_err(r#"{"clutter": [], "extra": ["zzz.png"]}"#);
        assert!(e.contains("split.json") && e.contains("zzz.png"), "{e}");
        std::fs::write(&p, r#"{"clutter": [1.5]}"#).unwrap();
        let e = read_split(&p).unwrap_err().to_string();
        assert!(
            e.contains("split.json") && e.contains("clutter[0]: 1.5 is not a whole-number index"),
            "{e}"
        );
        std::fs::write(&p, r#"{"clutter": [0, -1]}"#).unwrap();
        let e = read_split(&p).unwrap_err().to_string();
        assert!(
            e.contains("split.json: clutter[1]: index -1 is negative"),
            "{e}"
        );
        assert!(!e.contains("untagged"), "{e}");
        let e = resolve_err(r#"{"clutter": [0, 1], "extra": ["001.jpg"]}"#);
        assert!(
            e.contains("split.json") && e.contains("image 1 (001.jpg) is in both clutter"),
            "{e}"
        );
        std::fs::write(&p, "[1, 2]").unwrap();
        let e = read_split(&p).unwrap_err().to_string();
        assert!(e.contains("expected an object"), "{e}");
    }
}
