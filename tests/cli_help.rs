//! `--help` and the README say the same, and say all of it.

use std::collections::BTreeSet;

use tacmesh::daemon::sensor::SpecKind;

use crate::util::tacmesh_ok;

fn readme() -> String {
    std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/README.md")).expect("README")
}

/// The long options (`--name`) in `text`.
fn long_options(text: &str) -> BTreeSet<String> {
    text.split(|c: char| !(c.is_ascii_alphanumeric() || c == '-'))
        .filter(|word| word.starts_with("--") && word.len() > 2)
        .map(str::to_owned)
        .collect()
}

/// The options `tacmesh SUBCOMMAND --help` lists, apart from the ones every command has.
fn options_of(subcommand: &str) -> BTreeSet<String> {
    let help = tacmesh_ok(&[subcommand, "--help"]);
    let listed: String = help
        .lines()
        .filter(|line| line.trim_start().starts_with("--") || line.trim_start().starts_with("-v"))
        .map(|line| {
            line.split_whitespace()
                .find(|w| w.starts_with("--"))
                .unwrap_or("")
        })
        .collect::<Vec<_>>()
        .join(" ");
    let mut options = long_options(&listed);
    for common in ["--help", "--verbose", "--version"] {
        options.remove(common);
    }
    options
}

/// Every spec prefix the parser accepts (its own table, `SpecKind::ALL`) is in `tacmesh run
/// --help` and in the README's sensor table: a new backend without help fails here.
#[test]
fn run_help_and_readme_name_every_sensor_spec_prefix() {
    let help = tacmesh_ok(&["run", "--help"]);
    let readme = readme();
    let sensors = readme
        .split("## Sensors")
        .nth(1)
        .expect("the README has a Sensors section");
    for kind in SpecKind::ALL {
        let prefix = kind.prefix();
        assert!(
            help.contains(prefix),
            "`run --help` does not mention {prefix}"
        );
        assert!(
            sensors.contains(&format!("`{prefix}")),
            "the README's sensor table does not mention {prefix}"
        );
    }
    // And what each option does is up to date.
    assert!(help.contains("replay:PATH?fx="), "{help}");
    assert!(help.contains("/tmp/tacmesh-UID/tacmesh.sock"), "{help}");
    assert!(!help.contains("simulated sensors only"), "{help}");
}

/// The README's synopsis lines of `run` and `subscribe` list exactly the options their
/// `--help` does.
#[test]
fn readme_synopsis_lists_the_options_of_run_and_subscribe() {
    let readme = readme();
    for subcommand in ["run", "subscribe"] {
        let start = format!("tacmesh {subcommand} [");
        let synopsis = readme
            .lines()
            .find(|line| line.starts_with(&start))
            .unwrap_or_else(|| panic!("no README synopsis line `{start}…`"));
        assert_eq!(
            long_options(synopsis),
            options_of(subcommand),
            "README synopsis vs `tacmesh {subcommand} --help`"
        );
    }
}
