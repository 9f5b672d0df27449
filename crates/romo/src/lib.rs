//! romo crate.
