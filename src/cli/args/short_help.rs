//! What `-h` leaves out (issue 39): the common flags on one screen, the rest under `--help`.

/// `-h` for the common path (issue 39), for a command's `#[command(mut_args(...))]`: the flags
/// under "Advanced" and the ids in `brief` are left out of `-h` (`--help` shows them); the ids in
/// `hidden` are shown by neither, and still parse ([`NO_IDS`] for no such ids).
pub fn short_help(
    brief: impl IntoIterator<Item = impl ToString>,
    hidden: impl IntoIterator<Item = impl ToString>,
) -> impl FnMut(clap::Arg) -> clap::Arg {
    let brief: Vec<String> = brief.into_iter().map(|s| s.to_string()).collect();
    let hidden: Vec<String> = hidden.into_iter().map(|s| s.to_string()).collect();
    move |a| {
        let id = a.get_id().to_string();
        if hidden.contains(&id) {
            a.hide(true)
        } else if a.get_help_heading() == Some("Advanced") || brief.contains(&id) {
            a.hide_short_help(true)
        } else {
            a
        }
    }
}

/// No ids, for either list of [`short_help`].
pub const NO_IDS: [&str; 0] = [];

/// What the help says under the flags when [`short_help`] left some out of `-h`.
pub const SHORT_HELP_NOTE: &str = "-h shows the common flags; --help shows every flag (the \
Advanced ones too) and the full descriptions.";

#[cfg(test)]
mod tests {
    use clap::CommandFactory;

    /// Every id a command's [`super::short_help`] leaves out of `-h` is one of its flags: a
    /// misspelt id would leave its flag on the short screen without a word.
    #[test]
    fn short_help_names_only_flags_of_its_command() {
        let cli = crate::cli::Cli::command();
        let lists: [(&[&str], &[&str]); 5] = [
            (&["train"], &super::super::TRAIN_SHORT_HIDES),
            (&["bench", "train"], &super::super::TRAIN_SHORT_HIDES),
            (&["train-dynamic"], &crate::cli::train_dynamic::SHORT_HIDES),
            (&["rollout"], &crate::cli::rollout::SHORT_HIDES),
            (&["compare"], &crate::cli::compare::SHORT_HIDES),
        ];
        for (path, ids) in lists {
            let mut cmd = &cli;
            for name in path {
                cmd = cmd
                    .find_subcommand(name)
                    .unwrap_or_else(|| panic!("no command {path:?}"));
            }
            let flags: Vec<String> = cmd
                .get_arguments()
                .map(|a| a.get_id().to_string())
                .collect();
            for id in ids {
                assert!(
                    flags.iter().any(|f| f == id),
                    "garmentbake {} has no flag with the id {id}",
                    path.join(" ")
                );
            }
        }
    }
}
