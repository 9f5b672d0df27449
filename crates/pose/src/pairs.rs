//! What COLMAP's matcher found, read from its database, to name the cause
//! when the mapper builds no model.
//!
//! After geometric verification COLMAP stores, per image pair, the number of
//! inlier matches and the relation it fitted (`two_view_geometries.config`):
//! a general epipolar geometry (calibrated or uncalibrated) or a homography
//! (planar, panoramic, or planar-or-panoramic). A homography relates two
//! views exactly when the camera only rotated between them or the scene is
//! flat; neither gives the parallax triangulation needs. When every verified
//! pair is a homography, "no parallax" is the cause, not missing features.

use crate::error::{PoseError, Result};
use std::path::Path;

/// Counts of image pairs by what COLMAP's geometric verification found.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct PairStats {
    /// Pairs with raw feature matches.
    pub matched: usize,
    /// Pairs that passed geometric verification (inliers > 0).
    pub verified: usize,
    /// Verified pairs with a general epipolar geometry (parallax).
    pub general: usize,
    /// Verified pairs explained by a homography (rotation or a flat scene).
    pub homography: usize,
    /// Images in the database.
    #[serde(default)]
    pub images: usize,
    /// SIFT keypoints over all images (after masking).
    #[serde(default)]
    pub keypoints: usize,
}

/// Fewer keypoints per image than this on average and matching fails for
/// want of features, not of geometry: COLMAP's default mapper needs
/// 15 verified inliers per pair (`TwoViewGeometry` `min_num_inliers`), and
/// SIFT on a textured 480p frame finds thousands.
const MIN_KEYPOINTS_PER_IMAGE: usize = 50;

/// COLMAP's `TwoViewGeometry::ConfigurationType` values.
const CALIBRATED: i64 = 2;
const UNCALIBRATED: i64 = 3;
const PLANAR: i64 = 4;
const PANORAMIC: i64 = 5;
const PLANAR_OR_PANORAMIC: i64 = 6;

impl PairStats {
    /// Tally pairs from `(inlier rows, config)` rows of
    /// `two_view_geometries` and the number of pairs with raw matches.
    pub fn from_rows(matched: usize, rows: impl IntoIterator<Item = (i64, i64)>) -> Self {
        let mut s = PairStats {
            matched,
            ..PairStats::default()
        };
        for (inliers, config) in rows {
            if inliers <= 0 {
                continue;
            }
            s.verified += 1;
            match config {
                CALIBRATED | UNCALIBRATED => s.general += 1,
                PLANAR | PANORAMIC | PLANAR_OR_PANORAMIC => s.homography += 1,
                _ => {}
            }
        }
        s
    }

    /// Every verified pair is explained by a homography: the camera only
    /// rotated (or the scene is flat).
    pub fn no_parallax(&self) -> bool {
        self.verified > 0 && self.general == 0 && self.homography == self.verified
    }

    /// The cause of a failed reconstruction these counts point to, if they
    /// point to one.
    pub fn cause(&self) -> Option<String> {
        if self.images > 0 && self.keypoints < MIN_KEYPOINTS_PER_IMAGE * self.images {
            Some(format!(
                "SIFT found {} features in {} images ({:.0} per image): the frames have too little texture, or the masks cover most of each frame",
                self.keypoints,
                self.images,
                self.keypoints as f64 / self.images as f64
            ))
        } else if self.verified == 0 {
            Some(format!(
                "no image pair passed geometric verification ({} pairs had raw matches): too few static features match",
                self.matched
            ))
        } else if self.no_parallax() {
            Some(format!(
                "no parallax: all {} verified image pairs are related by a homography (the camera only rotated, or the scene is flat), so nothing can be triangulated; film while moving the camera sideways",
                self.verified
            ))
        } else {
            None
        }
    }
}

/// Read the pair counts from a COLMAP database.
pub fn read_pair_stats(db: &Path) -> Result<PairStats> {
    let err = |e: rusqlite::Error| PoseError::Database {
        path: db.to_path_buf(),
        reason: e.to_string(),
    };
    let conn =
        rusqlite::Connection::open_with_flags(db, rusqlite::OpenFlags::SQLITE_OPEN_READ_ONLY)
            .map_err(err)?;
    let matched: i64 = conn
        .query_row("SELECT COUNT(*) FROM matches WHERE rows > 0", [], |r| {
            r.get(0)
        })
        .map_err(err)?;
    let mut stmt = conn
        .prepare("SELECT rows, config FROM two_view_geometries")
        .map_err(err)?;
    let rows = stmt
        .query_map([], |r| Ok((r.get::<_, i64>(0)?, r.get::<_, i64>(1)?)))
        .map_err(err)?
        .collect::<std::result::Result<Vec<_>, _>>()
        .map_err(err)?;
    let (images, keypoints): (i64, Option<i64>) = conn
        .query_row("SELECT COUNT(*), SUM(rows) FROM keypoints", [], |r| {
            Ok((r.get(0)?, r.get(1)?))
        })
        .map_err(err)?;
    let count = |n: i64| usize::try_from(n).unwrap_or(0);
    Ok(PairStats {
        images: count(images),
        keypoints: count(keypoints.unwrap_or(0)),
        ..PairStats::from_rows(count(matched), rows)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn all_homographies_is_no_parallax() {
        let s = PairStats::from_rows(10, vec![(400, PLANAR_OR_PANORAMIC); 10]);
        assert_eq!(s.homography, 10);
        assert!(s.cause().is_some_and(|c| c.starts_with("no parallax")));
    }

    #[test]
    fn one_general_pair_is_not_no_parallax() {
        // The synthetic demo scene: most adjacent frames fit a homography,
        // a few wider pairs do not, and COLMAP reconstructs it.
        let mut rows = vec![(400, PLANAR_OR_PANORAMIC); 52];
        rows.extend(vec![(300, UNCALIBRATED); 5]);
        assert_eq!(PairStats::from_rows(57, rows).cause(), None);
    }

    #[test]
    fn nothing_verified_is_too_few_features() {
        let s = PairStats::from_rows(3, vec![(0, 0), (0, 0)]);
        assert!(
            s.cause()
                .is_some_and(|c| c.contains("too few static features"))
        );
    }

    #[test]
    fn too_few_keypoints_is_no_texture() {
        // A flat grey video: SIFT finds nothing, so nothing matches.
        let s = PairStats {
            images: 14,
            keypoints: 30,
            ..PairStats::from_rows(0, vec![])
        };
        assert!(s.cause().is_some_and(|c| c.contains("too little texture")));
        let textured = PairStats {
            images: 14,
            keypoints: 14 * 2000,
            ..PairStats::from_rows(0, vec![])
        };
        assert!(
            textured
                .cause()
                .is_some_and(|c| c.contains("too few static features"))
        );
    }

    #[test]
    fn reads_a_colmap_shaped_database() {
        let dir = tempfile::tempdir().unwrap();
        let db = dir.path().join("database.db");
        let conn = rusqlite::Connection::open(&db).unwrap();
        conn.execute_batch(
            "CREATE TABLE keypoints (image_id INTEGER PRIMARY KEY, rows INTEGER, cols INTEGER, data BLOB);
             INSERT INTO keypoints VALUES (1, 900, 6, NULL), (2, 700, 6, NULL), (3, 800, 6, NULL);
             CREATE TABLE matches (pair_id INTEGER PRIMARY KEY, rows INTEGER, cols INTEGER, data BLOB);
             CREATE TABLE two_view_geometries (pair_id INTEGER PRIMARY KEY, rows INTEGER, cols INTEGER, data BLOB, config INTEGER);
             INSERT INTO matches VALUES (1, 500, 2, NULL), (2, 400, 2, NULL), (3, 0, 2, NULL);
             INSERT INTO two_view_geometries VALUES (1, 450, 2, NULL, 5), (2, 380, 2, NULL, 6);",
        )
        .unwrap();
        drop(conn);
        let s = read_pair_stats(&db).unwrap();
        assert_eq!(
            s,
            PairStats {
                matched: 2,
                verified: 2,
                general: 0,
                homography: 2,
                images: 3,
                keypoints: 2400
            }
        );
        let e = read_pair_stats(&dir.path().join("missing.db")).unwrap_err();
        assert!(e.to_string().contains("missing.db"), "{e}");
    }
}
