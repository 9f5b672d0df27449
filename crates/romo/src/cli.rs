//! Command-line flags of the option structs (feature `cli`).
//!
//! [`RomoOptions`](crate::RomoOptions) and its nested option structs derive
//! `clap::Args`, each flag documented on its field. A command flattens
//! [`Flags<RomoOptions>`](Flags) and applies the flags the user gave over a
//! base (the defaults, or an options file) with [`Flags::apply`]: flags
//! override the file, the file overrides the defaults, and no default is
//! written a second time on the command line. Fields without a flag keep
//! the base's value.

use clap::parser::ValueSource;
use clap::{ArgMatches, Args, Command, FromArgMatches};
use std::marker::PhantomData;

/// The flags of the option struct `T` that were given on the command line.
pub struct Flags<T> {
    matches: ArgMatches,
    _options: PhantomData<fn() -> T>,
}

impl<T> std::fmt::Debug for Flags<T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Flags")
            .field("matches", &self.matches)
            .finish()
    }
}

impl<T> Clone for Flags<T> {
    fn clone(&self) -> Self {
        Self {
            matches: self.matches.clone(),
            _options: PhantomData,
        }
    }
}

impl<T: Args + FromArgMatches> Flags<T> {
    /// Set the fields of `base` whose flags were given.
    pub fn apply(&self, base: &mut T) -> Result<(), clap::Error> {
        base.update_from_arg_matches(&self.matches)
    }

    /// `base` with the given flags applied.
    pub fn over(&self, mut base: T) -> Result<T, clap::Error> {
        self.apply(&mut base)?;
        Ok(base)
    }
}

impl<T: Args> FromArgMatches for Flags<T> {
    fn from_arg_matches(matches: &ArgMatches) -> Result<Self, clap::Error> {
        let mut matches = matches.clone();
        // On/off flags (`--overlays`, `--no-cheirality`) carry clap's
        // implicit default; keep only what the user typed, so an absent
        // flag leaves the base's value.
        for arg in T::augment_args(Command::new("flags")).get_arguments() {
            let id = arg.get_id().as_str();
            if matches.value_source(id) == Some(ValueSource::DefaultValue) {
                matches
                    .try_clear_id(id)
                    .map_err(|e| clap::Error::raw(clap::error::ErrorKind::ArgumentConflict, e))?;
            }
        }
        Ok(Self {
            matches,
            _options: PhantomData,
        })
    }

    fn update_from_arg_matches(&mut self, matches: &ArgMatches) -> Result<(), clap::Error> {
        *self = Self::from_arg_matches(matches)?;
        Ok(())
    }
}

impl<T: Args> Args for Flags<T> {
    fn group_id() -> Option<clap::Id> {
        T::group_id()
    }

    fn augment_args(cmd: Command) -> Command {
        T::augment_args(cmd)
    }

    fn augment_args_for_update(cmd: Command) -> Command {
        T::augment_args_for_update(cmd)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::RomoOptions;
    use crate::objects::ObjectMethod;

    #[derive(clap::Parser)]
    struct Cmd {
        #[command(flatten)]
        romo: Flags<RomoOptions>,
    }

    fn parse(args: &[&str]) -> Flags<RomoOptions> {
        use clap::Parser;
        Cmd::try_parse_from(std::iter::once("t").chain(args.iter().copied()))
            .unwrap()
            .romo
    }

    /// Every flag has its own id: two flattened structs with a field of
    /// the same name (`enabled`) would otherwise share one, and one flag
    /// would set both fields.
    #[test]
    fn flag_ids_are_unique() {
        use clap::CommandFactory;
        let mut ids: Vec<String> = Cmd::command()
            .get_arguments()
            .map(|a| a.get_id().to_string())
            .collect();
        let n = ids.len();
        ids.sort();
        ids.dedup();
        assert_eq!(ids.len(), n, "{ids:?}");
    }

    /// No flags: the base comes back unchanged, on/off fields included.
    #[test]
    fn absent_flags_keep_the_base() {
        let mut base = RomoOptions {
            iterations: 3,
            overlays: true,
            chromaticity_features: false,
            ..Default::default()
        };
        base.labels.cheirality = false;
        base.regions.k = 9.0;
        let got = parse(&[]).over(base.clone()).unwrap();
        assert_eq!(
            serde_json::to_value(&got).unwrap(),
            serde_json::to_value(&base).unwrap()
        );
    }

    /// Given flags set their fields, nested ones included, and nothing else.
    #[test]
    fn given_flags_override_the_base() {
        let base: RomoOptions = serde_json::from_str(r#"{"iterations":3,"seed":5}"#).unwrap();
        let got = parse(&[
            "--iterations",
            "1",
            "--no-cheirality",
            "--no-image-fixed",
            "--overlays",
            "--region-k",
            "2.5",
            "--objects",
            "off",
            "--model-selection",
            "gric",
            "--onnx-flow",
            "m.onnx",
        ])
        .over(base)
        .unwrap();
        assert_eq!(got.iterations, 1);
        assert_eq!(got.seed, 5);
        assert!(!got.labels.cheirality);
        assert!(!got.overlay.enabled);
        assert!(got.regions.enabled);
        assert!(got.labels.three_view);
        assert!(got.overlays);
        assert_eq!(got.regions.k, 2.5);
        assert_eq!(got.refine.objects.method, ObjectMethod::Off);
        assert_eq!(
            got.labels.robust.selection,
            crate::geometry::robust::ModelSelection::Gric
        );
        assert_eq!(
            got.flow_backend,
            crate::FlowBackend::Onnx {
                model: "m.onnx".into()
            }
        );
        use clap::Parser;
        assert!(Cmd::try_parse_from(["t", "--region-k", "big"]).is_err());
    }
}
