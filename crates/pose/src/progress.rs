//! COLMAP's progress, read from its log lines (COLMAP 3.8 prints no machine
//! readable progress). [`parse_line`] is a pure function from one log line to
//! a count, so the formats it knows are tested on captured lines.
//!
//! | step | line | count |
//! |---|---|---|
//! | `feature_extractor` | `Processed file [12/65]` | images extracted (12 of 65) |
//! | `sequential_matcher` | `Matching image [12/65] in 1.8s` | images matched |
//! | `exhaustive_matcher` | `Matching block [2/3, 1/3]` | blocks matched ((2−1)·3 + 1 = 4 of 9) |
//! | `mapper` | `Registering image #18 (3)` | images registered (3; the total is the image count) |
//! | `image_undistorter` | `Undistorting image [4/65]` | images undistorted |

use serde::{Deserialize, Serialize};

/// What a count counts.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Unit {
    /// Images whose features were extracted.
    Extracted,
    /// Images (sequential) matched against their neighbours.
    Matched,
    /// Blocks of image pairs matched (exhaustive matcher).
    Blocks,
    /// Images registered by the mapper.
    Registered,
    /// Images undistorted.
    Undistorted,
}

impl Unit {
    /// Lower-case name for progress lines.
    pub fn name(self) -> &'static str {
        match self {
            Unit::Extracted => "images extracted",
            Unit::Matched => "images matched",
            Unit::Blocks => "blocks matched",
            Unit::Registered => "images registered",
            Unit::Undistorted => "images undistorted",
        }
    }
}

/// One progress reading.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Count {
    /// What is counted.
    pub unit: Unit,
    /// Done so far.
    pub done: u64,
    /// Out of; `None` when the line does not say (the mapper).
    pub total: Option<u64>,
}

/// `[a/b]` → (a, b).
fn fraction(s: &str) -> Option<(u64, u64)> {
    let (a, b) = s.trim().split_once('/')?;
    Some((a.trim().parse().ok()?, b.trim().parse().ok()?))
}

/// The text between the first `[` and the following `]`.
fn bracket(s: &str) -> Option<&str> {
    let start = s.find('[')? + 1;
    let len = s[start..].find(']')?;
    Some(&s[start..start + len])
}

/// Parse one COLMAP 3.8 log line into a progress count; `None` for every
/// other line.
pub fn parse_line(line: &str) -> Option<Count> {
    let l = line.trim();
    let simple = |unit: Unit| {
        let (done, total) = fraction(bracket(l)?)?;
        Some(Count {
            unit,
            done,
            total: Some(total),
        })
    };
    if l.starts_with("Processed file [") {
        return simple(Unit::Extracted);
    }
    if l.starts_with("Matching image [") {
        return simple(Unit::Matched);
    }
    if l.starts_with("Undistorting image [") {
        return simple(Unit::Undistorted);
    }
    if l.starts_with("Matching block [") {
        let (a, b) = bracket(l)?.split_once(',')?;
        let (i, n) = fraction(a)?;
        let (j, m) = fraction(b)?;
        if i == 0 || j == 0 {
            return None;
        }
        return Some(Count {
            unit: Unit::Blocks,
            done: (i - 1) * m + j,
            total: Some(n * m),
        });
    }
    if let Some(rest) = l.strip_prefix("Registering image #") {
        let inner = rest.split_once('(')?.1.split_once(')')?.0;
        return Some(Count {
            unit: Unit::Registered,
            done: inner.trim().parse().ok()?,
            total: None,
        });
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Lines captured from COLMAP 3.8 runs on the small built-in scene.
    #[test]
    fn parses_captured_colmap_lines() {
        let c = |unit, done, total| Some(Count { unit, done, total });
        for (line, want) in [
            ("Processed file [12/30]", c(Unit::Extracted, 12, Some(30))),
            (
                "Matching image [11/30] in 2.123s",
                c(Unit::Matched, 11, Some(30)),
            ),
            // A killed matcher leaves a line without its timing.
            ("Matching image [11/30]", c(Unit::Matched, 11, Some(30))),
            (
                "Matching block [2/3, 1/3] in 4.5s",
                c(Unit::Blocks, 4, Some(9)),
            ),
            ("Registering image #18 (3)", c(Unit::Registered, 3, None)),
            (
                "  Undistorting image [4/30]",
                c(Unit::Undistorted, 4, Some(30)),
            ),
        ] {
            assert_eq!(parse_line(line), want, "{line:?}");
        }
    }

    #[test]
    fn other_lines_are_not_progress() {
        for l in [
            "",
            "  Name:            00000.png",
            "  SKIP: Features for image already extracted.",
            "Initializing with image pair #19 and #11",
            "  => No good initial image pair found.",
            "Elapsed time: 0.149 [minutes]",
            "Processed file [x/30]",
            "Matching block [0/3, 1/3]",
            "Registering image #18",
        ] {
            assert_eq!(parse_line(l), None, "{l}");
        }
    }
}
