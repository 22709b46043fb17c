//! ARCHITECTURE.md's rules, checked: a rule the code stops keeping fails here, not in a review.
//!
//! - the crate graph of `[dependencies]` (the arrows of ARCHITECTURE.md's "Crates"): `protocol`
//!   a leaf above `conventions`, `scene` without the wire, the process crates never importing one
//!   another, the viewer without `scene`, and the shipped launcher without the benchmarks, the
//!   test harness, plotting or metric crates;
//! - no source file outside `tests/` over 600 lines;
//! - clap only in `cli.rs` and `main.rs`;
//! - no unbounded channel in a product crate but those named in ARCHITECTURE.md;
//! - every module a crate declares at its root named in ARCHITECTURE.md's map.
//!
//! Each rule is a function from the files to the list of its violations, so the rules themselves
//! are tested on made-up inputs below, and the real check prints every violation at once.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// Which of our crates each crate may list under `[dependencies]`. `testkit` (the test harness)
/// and `bench` (the benchmarks) are harnesses: they may link what they drive.
const ALLOWED: &[(&str, &[&str])] = &[
    ("conventions", &[]),
    ("protocol", &["conventions"]),
    ("scene", &["conventions"]),
    ("renderer", &["conventions", "protocol", "scene"]),
    ("sma", &["conventions", "protocol", "scene"]),
    ("viewer", &["conventions", "protocol"]),
    ("testkit", &["conventions", "protocol", "scene", "renderer"]),
    (
        "bench",
        &[
            "conventions",
            "protocol",
            "scene",
            "renderer",
            "sma",
            "viewer",
            "testkit",
        ],
    ),
    (
        "walkthrough",
        &[
            "conventions",
            "protocol",
            "scene",
            "renderer",
            "sma",
            "viewer",
        ],
    ),
];

/// Third-party crates that only the harnesses may link: the shipped binaries carry no plotting,
/// image-metric or test crate.
const HARNESS_ONLY: &[&str] = &["plotters", "nv-flip", "proptest", "tempfile"];

/// How an unbounded channel is made: tokio's and crossbeam's by name, std's without a bound
/// (`mpsc::channel()`, `channel::<T>()`; tokio's `mpsc::channel(n)` is bounded).
const UNBOUNDED: &[&str] = &["unbounded_channel(", "channel()", "unbounded()"];

fn makes_unbounded_channel(line: &str) -> bool {
    // A oneshot channel carries one message: bounded by its nature.
    !line.contains("oneshot::") && UNBOUNDED.iter().any(|call| line.contains(call))
        || line
            .split_once("channel::<")
            .is_some_and(|(_, rest)| rest.contains(">()"))
}

/// The longest source file ARCHITECTURE.md allows outside `tests/`.
const MAX_LINES: usize = 600;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// Every package of the workspace: its name and manifest folder.
fn packages() -> Vec<(String, PathBuf)> {
    let manifest = read_toml(&root().join("Cargo.toml"));
    let mut packages = vec![("walkthrough".to_string(), root())];
    for member in manifest["workspace"]["members"]
        .as_array()
        .expect("members")
    {
        let dir = root().join(member.as_str().expect("a member path"));
        let name = read_toml(&dir.join("Cargo.toml"))["package"]["name"]
            .as_str()
            .expect("a package name")
            .to_string();
        packages.push((name, dir));
    }
    packages
}

fn read_toml(path: &Path) -> toml::Table {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    text.parse()
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// The names under a manifest's `[dependencies]` (not dev- or build-dependencies).
fn normal_dependencies(manifest: &toml::Table) -> BTreeSet<String> {
    manifest
        .get("dependencies")
        .and_then(|d| d.as_table())
        .map(|d| d.keys().cloned().collect())
        .unwrap_or_default()
}

/// Violations of the crate graph: a dependency on one of our crates that [`ALLOWED`] does not
/// list, a harness-only crate in a product crate, or a package the table does not know.
fn graph_violations(deps: &BTreeMap<String, BTreeSet<String>>) -> Vec<String> {
    let ours: BTreeSet<&str> = ALLOWED.iter().map(|(name, _)| *name).collect();
    let mut violations = Vec::new();
    for (package, uses) in deps {
        let Some((_, allowed)) = ALLOWED.iter().find(|(name, _)| name == package) else {
            violations.push(format!(
                "{package}: not in the crate graph of ARCHITECTURE.md"
            ));
            continue;
        };
        let harness = matches!(package.as_str(), "testkit" | "bench");
        for dep in uses {
            if ours.contains(dep.as_str()) && !allowed.contains(&dep.as_str()) {
                violations.push(format!("{package} depends on {dep}"));
            }
            if !harness && HARNESS_ONLY.contains(&dep.as_str()) {
                violations.push(format!("{package} (a product crate) links {dep}"));
            }
        }
    }
    violations
}

/// Every `.rs` file under a package's `src/` (not its `tests/`, `benches/` or `fuzz/`).
fn source_files() -> Vec<PathBuf> {
    let mut files = Vec::new();
    for (_, dir) in packages() {
        collect_rs(&dir.join("src"), &mut files);
    }
    files
}

fn collect_rs(dir: &Path, files: &mut Vec<PathBuf>) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for entry in entries.flatten() {
        let path = entry.path();
        if path.is_dir() {
            collect_rs(&path, files);
        } else if path.extension().is_some_and(|e| e == "rs") {
            files.push(path);
        }
    }
}

fn long_file_violations(files: &[(PathBuf, String)]) -> Vec<String> {
    files
        .iter()
        .filter(|(_, text)| text.lines().count() > MAX_LINES)
        .map(|(path, text)| {
            format!(
                "{}: {} lines (at most {MAX_LINES})",
                relative(path),
                text.lines().count()
            )
        })
        .collect()
}

/// The lines of a source file that are code, not comments.
fn code_lines(text: &str) -> impl Iterator<Item = &str> {
    text.lines()
        .map(str::trim_start)
        .filter(|line| !line.starts_with("//"))
}

fn clap_violations(files: &[(PathBuf, String)]) -> Vec<String> {
    files
        .iter()
        .filter(|(path, _)| {
            let name = path.file_name().and_then(|n| n.to_str()).unwrap_or("");
            name != "cli.rs" && name != "main.rs"
        })
        .filter(|(_, text)| code_lines(text).any(|line| line.contains("clap::")))
        .map(|(path, _)| format!("{}: uses clap outside cli.rs/main.rs", path.display()))
        .collect()
}

/// Unbounded channels in product code. One that must stay unbounded is named in
/// ARCHITECTURE.md's invariants by its file, with the reason; the check reads that list there.
fn unbounded_violations(files: &[(PathBuf, String)], named: &str) -> Vec<String> {
    files
        .iter()
        .filter(|(path, _)| !is_harness(path) && !path.ends_with("tests.rs"))
        .filter(|(_, text)| code_lines(product_part(text)).any(makes_unbounded_channel))
        .filter(|(path, _)| !named.contains(&relative(path)))
        .map(|(path, _)| {
            format!(
                "{}: an unbounded channel not named in ARCHITECTURE.md",
                relative(path)
            )
        })
        .collect()
}

/// A source file without its unit tests, which may queue as they like.
fn product_part(text: &str) -> &str {
    text.split_once("#[cfg(test)]\nmod tests")
        .map_or(text, |(product, _)| product)
}

fn is_harness(path: &Path) -> bool {
    let path = relative(path);
    path.starts_with("crates/testkit/") || path.starts_with("crates/bench/")
}

fn relative(path: &Path) -> String {
    path.strip_prefix(root())
        .unwrap_or(path)
        .to_string_lossy()
        .replace('\\', "/")
}

/// Modules declared at a crate root (`mod x;`, `pub mod x;`, `pub(crate) mod x;`).
fn root_modules(lib: &str) -> Vec<String> {
    code_lines(lib)
        .filter_map(|line| {
            let rest = line
                .strip_prefix("pub(crate) mod ")
                .or_else(|| line.strip_prefix("pub mod "))
                .or_else(|| line.strip_prefix("mod "))?;
            rest.strip_suffix(';').map(|name| name.trim().to_string())
        })
        .collect()
}

fn unmapped_modules(crates: &[(String, String)], map: &str) -> Vec<String> {
    crates
        .iter()
        .flat_map(|(krate, lib)| {
            root_modules(lib)
                .into_iter()
                .filter(|m| !named_in(map, m))
                .map(move |m| format!("{krate}::{m} is not in ARCHITECTURE.md's map"))
        })
        .collect()
}

/// A module counts as named when the map spells it alone (`` `cache` ``), as a path's last part
/// (`sma::cache`) or as a path's first part (`` `snapshot_painter::Frame` ``).
fn named_in(map: &str, module: &str) -> bool {
    [
        format!("`{module}`"),
        format!("::{module}"),
        format!("`{module}::"),
    ]
    .iter()
    .any(|spelling| map.contains(spelling.as_str()))
}

fn read_sources() -> Vec<(PathBuf, String)> {
    source_files()
        .into_iter()
        .map(|path| {
            let text = std::fs::read_to_string(&path).expect("a readable source file");
            (path, text)
        })
        .collect()
}

#[test]
fn architecture_md_rules_hold() {
    let deps: BTreeMap<String, BTreeSet<String>> = packages()
        .into_iter()
        .map(|(name, dir)| {
            (
                name,
                normal_dependencies(&read_toml(&dir.join("Cargo.toml"))),
            )
        })
        .collect();
    let sources = read_sources();
    let map = std::fs::read_to_string(root().join("ARCHITECTURE.md")).expect("ARCHITECTURE.md");
    let libs: Vec<(String, String)> = packages()
        .into_iter()
        .filter_map(|(name, dir)| {
            Some((name, std::fs::read_to_string(dir.join("src/lib.rs")).ok()?))
        })
        .collect();
    let mut violations = graph_violations(&deps);
    violations.extend(long_file_violations(&sources));
    violations.extend(clap_violations(&sources));
    violations.extend(unbounded_violations(&sources, &map));
    violations.extend(unmapped_modules(&libs, &map));
    assert!(
        violations.is_empty(),
        "ARCHITECTURE.md's rules are broken:\n  {}",
        violations.join("\n  ")
    );
}

#[test]
fn the_check_sees_every_package_and_its_sources() {
    let names: BTreeSet<String> = packages().into_iter().map(|(n, _)| n).collect();
    for expected in ["walkthrough", "protocol", "sma", "viewer", "bench"] {
        assert!(names.contains(expected), "{names:?}");
    }
    let sources = source_files();
    assert!(
        sources
            .iter()
            .any(|p| relative(p) == "crates/sma/src/lib.rs")
    );
    assert!(sources.iter().any(|p| relative(p) == "src/cli.rs"));
}

mod rules {
    use super::*;

    fn graph(entries: &[(&str, &[&str])]) -> BTreeMap<String, BTreeSet<String>> {
        entries
            .iter()
            .map(|(p, d)| (p.to_string(), d.iter().map(|s| s.to_string()).collect()))
            .collect()
    }

    #[test]
    fn a_process_crate_importing_another_breaks_the_graph() {
        assert!(graph_violations(&graph(&[("viewer", &["protocol", "glam"])])).is_empty());
        let broken = graph_violations(&graph(&[
            ("viewer", &["scene"]),
            ("sma", &["renderer"]),
            ("protocol", &["scene"]),
        ]));
        assert_eq!(broken.len(), 3, "{broken:?}");
    }

    #[test]
    fn the_launcher_linking_a_harness_breaks_the_graph() {
        let broken = graph_violations(&graph(&[("walkthrough", &["testkit", "plotters"])]));
        assert_eq!(broken.len(), 2, "{broken:?}");
        assert!(graph_violations(&graph(&[("bench", &["testkit", "plotters"])])).is_empty());
    }

    #[test]
    fn long_files_clap_and_unbounded_channels_are_found() {
        let long = (PathBuf::from("a.rs"), "x\n".repeat(MAX_LINES + 1));
        let short = (PathBuf::from("b.rs"), "x\n".repeat(MAX_LINES));
        assert_eq!(long_file_violations(&[long, short]).len(), 1);

        let clap_in_lib = (PathBuf::from("lib.rs"), "use clap::Parser;\n".to_string());
        let clap_in_cli = (PathBuf::from("cli.rs"), "use clap::Parser;\n".to_string());
        let clap_in_doc = (
            PathBuf::from("x.rs"),
            "//! only cli.rs knows clap::\n".to_string(),
        );
        assert_eq!(
            clap_violations(&[clap_in_lib, clap_in_cli, clap_in_doc]).len(),
            1
        );

        let channel = |p: &str| {
            (
                PathBuf::from(p),
                "let (a, b) = mpsc::unbounded_channel();".into(),
            )
        };
        let files = [
            channel("crates/viewer/src/x.rs"),
            channel("crates/viewer/src/y.rs"),
        ];
        assert_eq!(
            unbounded_violations(&files, "`crates/viewer/src/y.rs`").len(),
            1
        );
    }

    #[test]
    fn a_module_missing_from_the_map_is_found() {
        let lib = "pub mod cache;\npub(crate) mod schedule;\nmod hidden;\n// mod commented;\n";
        assert_eq!(root_modules(lib), ["cache", "schedule", "hidden"]);
        let missing = unmapped_modules(&[("sma".into(), lib.into())], "`cache`, `sma::schedule`");
        assert_eq!(missing, ["sma::hidden is not in ARCHITECTURE.md's map"]);
    }
}
