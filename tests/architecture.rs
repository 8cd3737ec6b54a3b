//! The tree keeps the architecture: no import cycles between the top-level modules
//! of the binary or of the pure crates, at most a dozen entries in `src/`, and no edge crate
//! named in the pure crates' sources. The libraries depend on each other only
//! downward, in the order [`LIBRARIES`] gives, and none holds more than 40 % of the lines.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // tests may fail loudly

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// The pure libraries, lowest first, each with the libraries it may depend on (all below it).
const LIBRARIES: [(&str, &[&str]); 6] = [
    ("mbtap-proto", &[]),
    ("mbtap-device", &["mbtap-proto"]),
    ("mbtap-analysis", &["mbtap-proto", "mbtap-device"]),
    ("mbtap-sim", &["mbtap-proto", "mbtap-device", "mbtap-analysis"]),
    ("mbtap-publish", &["mbtap-device"]),
    // The gateway's protocol facts (line settings, the serial mode, durations, the data model's
    // tables) are the protocol crate's: it stands on that crate alone, beside the others.
    ("mbtap-gateway", &["mbtap-proto"]),
];

fn library_src(root: &Path, krate: &str) -> PathBuf {
    root.join("crates").join(krate).join("src")
}

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for e in std::fs::read_dir(dir).unwrap().flatten() {
        let p = e.path();
        if p.is_dir() {
            rust_files(&p, out);
        } else if p.extension().is_some_and(|x| x == "rs") {
            out.push(p);
        }
    }
}

/// Top-level module → the top-level modules its code (not its comments) names as `crate::X`.
fn graph(src: &Path) -> BTreeMap<String, BTreeSet<String>> {
    let mut files = Vec::new();
    rust_files(src, &mut files);
    let mut g: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    for f in files {
        let rel = f.strip_prefix(src).unwrap();
        let first = rel.components().next().unwrap().as_os_str().to_string_lossy().trim_end_matches(".rs").to_owned();
        if matches!(first.as_str(), "lib" | "main") {
            continue;
        }
        let text = std::fs::read_to_string(&f).unwrap();
        let deps = g.entry(first.clone()).or_default();
        for line in text.lines().filter(|l| !l.trim_start().starts_with("//")) {
            for (i, _) in line.match_indices("crate::") {
                let name: String =
                    line[i + 7..].chars().take_while(|c| c.is_ascii_alphanumeric() || *c == '_').collect();
                if !name.is_empty() && name != first {
                    deps.insert(name);
                }
            }
        }
    }
    g
}

/// A cycle in `g`, if there is one.
fn cycle(g: &BTreeMap<String, BTreeSet<String>>) -> Option<Vec<String>> {
    fn visit(
        n: &str,
        g: &BTreeMap<String, BTreeSet<String>>,
        path: &mut Vec<String>,
        done: &mut BTreeSet<String>,
    ) -> Option<Vec<String>> {
        if let Some(i) = path.iter().position(|p| p == n) {
            return Some(path[i..].to_vec());
        }
        if done.contains(n) {
            return None;
        }
        path.push(n.to_owned());
        for d in g.get(n).into_iter().flatten() {
            if let Some(c) = visit(d, g, path, done) {
                return Some(c);
            }
        }
        path.pop();
        done.insert(n.to_owned());
        None
    }
    let mut done = BTreeSet::new();
    g.keys().find_map(|n| visit(n, g, &mut Vec::new(), &mut done))
}

#[test]
fn no_import_cycles_between_top_level_modules() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let libraries = LIBRARIES.iter().map(|(k, _)| library_src(root, k));
    for src in std::iter::once(root.join("src")).chain(libraries) {
        let g = graph(&src);
        assert!(g.len() > 3, "{}: modules not found", src.display());
        assert_eq!(cycle(&g), None, "an import cycle in {}", src.display());
    }
}

#[test]
fn src_shows_the_design_in_at_most_a_dozen_entries() {
    let entries = std::fs::read_dir(Path::new(env!("CARGO_MANIFEST_DIR")).join("src")).unwrap().count();
    assert!(entries <= 12, "src/ has {entries} entries");
}

#[test]
fn the_pure_crates_name_no_edge_crate() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    for (name, _) in LIBRARIES {
        let krate = format!("crates/{name}");
        let mut files = Vec::new();
        rust_files(&root.join(&krate).join("src"), &mut files);
        for f in files {
            let text = std::fs::read_to_string(&f).unwrap();
            for edge in ["tokio", "ratatui", "crossterm", "clap", "serialport", "std::time::Instant", "SystemTime"] {
                let used = text.lines().filter(|l| !l.trim_start().starts_with("//")).any(|l| l.contains(edge));
                assert!(!used, "{} names {edge}: the pure crates take time as an input", f.display());
            }
        }
        let manifest = std::fs::read_to_string(root.join(&krate).join("Cargo.toml")).unwrap();
        for edge in ["tokio", "ratatui", "crossterm", "clap", "serialport"] {
            assert!(!manifest.contains(edge), "{krate}/Cargo.toml depends on {edge}");
        }
    }
}

/// A library names in its manifest only the libraries below it, so no crate reaches
/// up (and no circle can form); every library is a workspace member.
#[test]
fn the_libraries_depend_only_downward() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let workspace = std::fs::read_to_string(root.join("Cargo.toml")).unwrap();
    for (name, allowed) in LIBRARIES {
        assert!(workspace.contains(&format!("\"crates/{name}\"")), "{name} is not a workspace member");
        let manifest = std::fs::read_to_string(root.join("crates").join(name).join("Cargo.toml")).unwrap();
        let deps = manifest.split("[dependencies]").nth(1).unwrap_or_default();
        for line in deps.lines().take_while(|l| !l.starts_with('[')) {
            let dep = line.split([' ', '=']).next().unwrap_or_default();
            if dep.starts_with("mbtap-") {
                assert!(allowed.contains(&dep), "{name} depends on {dep}: only {allowed:?} are below it");
            }
        }
    }
}

/// No library holds more than 40 % of the project's lines (src/ and crates/), so the
/// tree says where a change belongs.
#[test]
fn no_library_holds_more_than_two_fifths_of_the_lines() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let lines = |dir: &Path| {
        let mut files = Vec::new();
        rust_files(dir, &mut files);
        files.iter().map(|f| std::fs::read_to_string(f).unwrap().lines().count()).sum::<usize>()
    };
    let each: Vec<(&str, usize)> = LIBRARIES.iter().map(|(k, _)| (*k, lines(&library_src(root, k)))).collect();
    let total = lines(&root.join("src")) + each.iter().map(|(_, n)| n).sum::<usize>();
    for (name, n) in each {
        assert!(n * 5 <= total * 2, "{name} holds {n} of {total} lines");
    }
}

/// Per directory module: file → the sibling files its code names (`super::X`, `self::X` in mod.rs,
/// `crate::…::DIR::X`), comments left out. The top-level check alone cannot see circles between the
/// files of one module (`src/bridge/`, `src/tui/`).
fn file_graphs(src: &Path) -> Vec<(PathBuf, BTreeMap<String, BTreeSet<String>>)> {
    let mut dirs = vec![src.to_path_buf()];
    let mut out = Vec::new();
    while let Some(dir) = dirs.pop() {
        let mut siblings = BTreeSet::new();
        let mut files = Vec::new();
        for e in std::fs::read_dir(&dir).unwrap().flatten() {
            let p = e.path();
            if p.is_dir() {
                siblings.insert(p.file_name().unwrap().to_string_lossy().into_owned());
                dirs.push(p);
            } else if p.extension().is_some_and(|x| x == "rs") {
                siblings.insert(p.file_stem().unwrap().to_string_lossy().into_owned());
                files.push(p);
            }
        }
        let module = dir.strip_prefix(src).unwrap().to_string_lossy().replace('/', "::");
        let mut g: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
        for f in files {
            let me = f.file_stem().unwrap().to_string_lossy().into_owned();
            if matches!(me.as_str(), "mod" | "lib" | "main") {
                continue;
            }
            let text = std::fs::read_to_string(&f).unwrap();
            let deps = g.entry(me.clone()).or_default();
            let prefixes = if module.is_empty() {
                vec!["crate::".to_owned()]
            } else {
                vec!["super::".to_owned(), format!("crate::{module}::")]
            };
            for line in text.lines().filter(|l| !l.trim_start().starts_with("//")) {
                for prefix in &prefixes {
                    for (i, _) in line.match_indices(prefix.as_str()) {
                        // `super::super::…` leaves this directory: not a sibling.
                        let rest = &line[i + prefix.len()..];
                        let name: String =
                            rest.chars().take_while(|c| c.is_ascii_alphanumeric() || *c == '_').collect();
                        if name != me && siblings.contains(&name) && name != "super" {
                            deps.insert(name);
                        }
                    }
                }
            }
        }
        out.push((dir, g));
    }
    out
}

#[test]
fn no_import_circles_between_the_files_of_a_module() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut circles = Vec::new();
    let libraries = LIBRARIES.iter().map(|(k, _)| library_src(root, k));
    for src in std::iter::once(root.join("src")).chain(libraries) {
        for (dir, g) in file_graphs(&src) {
            if let Some(c) = cycle(&g) {
                circles.push(format!("{}: {}", dir.display(), c.join(" → ")));
            }
        }
    }
    assert!(circles.is_empty(), "import circles between files:\n{}", circles.join("\n"));
}

/// The gateway core is pure by what it links, not only by what it names — no async runtime,
/// serial or socket crate anywhere under it, nor the analysis crate.
#[test]
fn the_gateway_core_links_no_runtime_port_or_socket_crate() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let out = std::process::Command::new(env!("CARGO"))
        .args(["tree", "--offline", "-p", "mbtap-gateway", "-e", "normal", "--prefix", "none"])
        .current_dir(root)
        .output()
        .unwrap();
    assert!(out.status.success(), "cargo tree: {}", String::from_utf8_lossy(&out.stderr));
    let tree = String::from_utf8_lossy(&out.stdout);
    assert!(tree.contains("mbtap-gateway"), "{tree}");
    for line in tree.lines() {
        let name = line.split_whitespace().next().unwrap_or_default();
        for edge in [
            "tokio",
            "mio",
            "serialport",
            "serial2",
            "nix",
            "socket2",
            "rustls",
            "clap",
            "ratatui",
            "crossterm",
            "mbtap-analysis",
        ] {
            assert!(!name.starts_with(edge), "mbtap-gateway links {name}");
        }
    }
}

/// The README's Layout names every crate of the workspace and no crate that is not there, and
/// every module a crate's `lib.rs` declares is named in its line of the layout: the map stays
/// true to the tree.
#[test]
fn the_readmes_layout_names_every_crate_and_its_modules() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let readme = std::fs::read_to_string(root.join("README.md")).unwrap();
    let layout = readme.split("## Layout").nth(1).unwrap().split("\n## ").next().unwrap();
    let crates: Vec<String> = std::fs::read_dir(root.join("crates"))
        .unwrap()
        .filter_map(|e| e.ok().filter(|e| e.path().join("Cargo.toml").exists()))
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .collect();
    for c in &crates {
        assert!(layout.contains(&format!("crates/{c}/")), "the Layout does not name crates/{c}/");
    }
    for named in layout.split("crates/").skip(1).filter_map(|s| s.split('/').next()) {
        assert!(crates.iter().any(|c| c == named), "the Layout names crates/{named}/, which is not there");
    }
    // Every room of the binary's src/, each named in the Layout.
    for e in std::fs::read_dir(root.join("src")).unwrap().flatten() {
        let name = e.file_name().to_string_lossy().into_owned();
        let named = if e.path().is_dir() { format!("src/{name}/") } else { format!("src/{name}") };
        if name != "lib.rs" {
            assert!(layout.contains(&named), "the Layout does not name {named}");
        }
    }
    // The gateway's modules, each named in its entry.
    let entry = layout.split("crates/mbtap-gateway/").nth(1).unwrap().split("\nsrc/").next().unwrap();
    let lib = std::fs::read_to_string(root.join("crates/mbtap-gateway/src/lib.rs")).unwrap();
    for module in lib.lines().filter_map(|l| l.strip_prefix("pub mod ")).map(|m| m.trim_end_matches(';')) {
        if module == "fuzzing" || module == "parse" {
            continue;
        }
        assert!(entry.contains(module), "the Layout's gateway entry does not name its module {module}");
    }
}

/// Every module's map names its modules: a file that declares `mod X;` says in its own `//!`
/// doc what `X` holds, so a newcomer reading the map finds every room. Left out: test modules,
/// the fuzz bodies (`fuzzing`, one per library, named in the README) and `src/cmd/mod.rs`,
/// whose modules are the commands `mbtap --help` lists.
#[test]
fn every_module_map_names_its_modules() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut files = Vec::new();
    rust_files(&root.join("src"), &mut files);
    for e in std::fs::read_dir(root.join("crates")).unwrap().flatten() {
        if e.path().join("src").is_dir() {
            rust_files(&e.path().join("src"), &mut files);
        }
    }
    let mut unnamed = Vec::new();
    for f in files.iter().filter(|f| !f.ends_with("src/cmd/mod.rs")) {
        let text = std::fs::read_to_string(f).unwrap();
        let doc: String = text.lines().filter(|l| l.starts_with("//!")).collect::<Vec<_>>().join("\n");
        let mut previous = "";
        for line in text.lines() {
            let declared = line.trim_start_matches("pub ").trim_start_matches("pub(crate) ").strip_prefix("mod ");
            if let Some(name) = declared.and_then(|m| m.strip_suffix(';'))
                && !previous.contains("cfg(test)")
                && name != "fuzzing"
                && !doc.contains(name)
            {
                unnamed.push(format!("{}: {name}", f.strip_prefix(root).unwrap().display()));
            }
            previous = line.trim();
        }
    }
    assert!(unnamed.is_empty(), "modules their file's map does not name: {unnamed:#?}");
}
