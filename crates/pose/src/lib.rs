//! pose crate.
