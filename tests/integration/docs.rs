//! Every documented command runs as written: the `garmentbake …` / `$gb …` lines of the ```sh
//! blocks of README.md and docs/guide/*.md are extracted and run on the samples, page by page in
//! order, each page in its own scratch folder (`target/test-out/docs_*`: `samples/` there links
//! to the repository's, `out/` and `runs/` are made as `scripts/run_samples.sh` leaves them).
//! A command fails the test when it exits non-zero or does not write its `--out`.
//!
//! To fit CI the commands run with [`SHORT_SETTINGS`] (docs/guide/README.md says so): the same
//! commands, flags and files as on the page, shorter. Lines of a block that are not garmentbake
//! (`bash scripts/…`, `cargo …`, `ray …`) are not run; `gb=…` must name the binary and
//! `mkdir -p` makes its folders. A page that stops having commands fails too (a minimum count
//! per page), so a changed fence cannot make the test pass by running nothing.

use crate::common::*;
use std::ops::Range;
use std::path::PathBuf;
use std::process::Command;
use std::time::Instant;

/// What the test changes in a documented command so that the pages run in about a minute:
/// - `--epochs N` (N > 1) → `--epochs 1`;
/// - the PBNS commands (`train`, `train-swing`, `eval`, `bake`, `validate --model`) play their
///   clips at 1 fps (`--fps 1`, given or replaced);
/// - `simulate` → `--frames 6` with a 0.3 s lead-in (`--settle 0.1 --blend 0.2`) in the tests'
///   shared simulation cache (`common::sim_cache`), `rollout --frames N` → `--frames 6`;
/// - `train-dynamic --stage dynamic` → the learnt dynamics (the default, or
///   `--dynamics-epochs N > 0`) for one epoch through 2–3-frame windows (`--unroll-frames 2,3`:
///   six frames are shorter than the recipe's 32);
/// - the batch manifest (`samples/batch.toml`, copied into the scratch folder) keeps the skirt's
///   PBNS recipe alone, 1 epoch, its bakes (no point cache) for 131_02 only, the clips at 1 fps.
pub const SHORT_SETTINGS: &str = "epochs 1; PBNS clips at 1 fps; 6 simulated / rolled-out frames \
     with a 0.3 s lead-in; the learnt dynamics 1 epoch of 2-3-frame windows; the batch manifest cut to the skirt's PBNS bakes of 131_02";

const PBNS_CLIP_COMMANDS: [&str; 5] = ["train", "train-swing", "eval", "bake", "validate"];

/// One documented command: where it is, its words after the program, and a `> FILE` if any.
#[derive(Debug)]
enum Step {
    Run {
        at: String,
        args: Vec<String>,
        stdout_to: Option<String>,
    },
    Mkdir(Vec<String>),
}

/// Shell words of a line: whitespace-separated, '…' and "…" quoting, no expansions (a `$`
/// other than `$gb` at the start is refused, so a page cannot rely on what the test skips).
fn words(line: &str, at: &str) -> Vec<String> {
    let (mut out, mut cur, mut quote, mut any) = (Vec::new(), String::new(), None, false);
    for c in line.chars() {
        match (quote, c) {
            (Some(q), c) if c == q => quote = None,
            (Some(_), c) => cur.push(c),
            (None, '\'' | '"') => {
                quote = Some(c);
                any = true
            }
            (None, c) if c.is_whitespace() => {
                if any || !cur.is_empty() {
                    out.push(std::mem::take(&mut cur));
                }
                any = false
            }
            (None, c) => cur.push(c),
        }
    }
    assert!(quote.is_none(), "{at}: unclosed quote in `{line}`");
    if any || !cur.is_empty() {
        out.push(cur);
    }
    out
}

/// The steps of the ```sh blocks of `page` (a path relative to the repository root), each with
/// the index of its block among the page's ```sh blocks.
fn steps(page: &str) -> Vec<(usize, Step)> {
    let text = std::fs::read_to_string(root().join(page)).expect("the page");
    let (mut steps, mut in_sh, mut pending, mut gb) = (Vec::new(), false, String::new(), false);
    let (mut start, mut block) = (0, 0);
    for (n, line) in text.lines().enumerate() {
        let fence = line.trim_start().starts_with("```");
        if fence {
            if in_sh {
                block += 1;
            }
            in_sh = !in_sh && line.trim() == "```sh";
            continue;
        }
        if !in_sh {
            continue;
        }
        if pending.is_empty() {
            start = n + 1;
        }
        // A comment: from a `#` that starts a word.
        let code = match line
            .find(" #")
            .or_else(|| line.starts_with('#').then_some(0))
        {
            Some(i) => &line[..i],
            None => line,
        };
        if let Some(head) = code.trim_end().strip_suffix('\\') {
            pending.push_str(head);
            pending.push(' ');
            continue;
        }
        pending.push_str(code);
        let line = std::mem::take(&mut pending);
        let at = format!("{page}:{start}");
        let mut w = words(line.trim(), &at);
        if w.is_empty() {
            continue;
        }
        if let Some(value) = w[0].strip_prefix("gb=") {
            assert_eq!(
                value, "target/release/garmentbake",
                "{at}: gb names another binary"
            );
            gb = true;
            continue;
        }
        if w[0] == "mkdir" {
            assert_eq!(
                w.get(1).map(String::as_str),
                Some("-p"),
                "{at}: mkdir without -p"
            );
            steps.push((block, Step::Mkdir(w[2..].to_vec())));
            continue;
        }
        let program = w[0].as_str();
        let ours = program == "garmentbake" || program.ends_with("/garmentbake");
        if program == "$gb" {
            assert!(gb, "{at}: $gb used before `gb=target/release/garmentbake`");
        } else if !ours {
            assert!(
                !line.contains("garmentbake ") || program == "cargo",
                "{at}: a garmentbake line the test cannot run: `{line}`"
            );
            continue;
        }
        assert!(
            !w[1..]
                .iter()
                .any(|x| x.contains('$') || x.contains('|') || x == "&&"),
            "{at}: expansions and pipes are not run by the test: `{line}`"
        );
        let stdout_to = match w.iter().position(|x| x == ">") {
            Some(i) => {
                let file = w.get(i + 1).cloned();
                w.truncate(i);
                file
            }
            None => None,
        };
        w.remove(0);
        steps.push((
            block,
            Step::Run {
                at,
                args: w,
                stdout_to,
            },
        ));
    }
    steps
}

fn set_flag(args: &mut Vec<String>, flag: &str, value: &str) {
    match args.iter().position(|a| a == flag) {
        Some(i) => args[i + 1] = value.to_string(),
        None => args.extend([flag.to_string(), value.to_string()]),
    }
}

/// [`SHORT_SETTINGS`] applied to one command's words.
fn shorten(args: &mut Vec<String>) {
    let command = args[0].clone();
    if let Some(i) = args.iter().position(|a| a == "--epochs") {
        if args[i + 1].parse::<usize>().expect("--epochs N") > 1 {
            args[i + 1] = "1".into();
        }
    }
    let has = |args: &[String], flag: &str| args.iter().any(|a| a == flag);
    if PBNS_CLIP_COMMANDS.contains(&command.as_str()) && has(args, "--motion") {
        set_flag(args, "--fps", "1");
    }
    if command == "simulate" {
        set_flag(args, "--frames", "6");
        for (flag, value) in [
            ("--settle", "0.1"),
            ("--blend", "0.2"),
            ("--cache", sim_cache()),
        ] {
            set_flag(args, flag, value);
        }
    }
    let stage = args
        .iter()
        .position(|a| a == "--stage")
        .map(|i| args[i + 1].as_str());
    if command == "train-dynamic" && stage == Some("dynamic") {
        let off = args
            .iter()
            .position(|a| a == "--dynamics-epochs")
            .is_some_and(|i| args[i + 1] == "0");
        if !off {
            set_flag(args, "--dynamics-epochs", "1");
            set_flag(args, "--unroll-frames", "2,3");
        }
    }
    if command == "rollout" && has(args, "--frames") {
        set_flag(args, "--frames", "6");
    }
}

/// The sample manifest cut to the skirt's PBNS recipe (see [`SHORT_SETTINGS`]).
fn short_manifest(text: &str) -> String {
    let mut m: toml::Table = text.parse().expect("samples/batch.toml");
    let clips = m.get_mut("clips").and_then(|c| c.as_array_mut());
    for clip in clips.expect("[[clips]]") {
        clip.as_table_mut().unwrap().insert("fps".into(), 1.into());
    }
    let garments = m.get_mut("garments").and_then(|g| g.as_array_mut());
    let garments = garments.expect("[[garments]]");
    garments.retain(|g| g.get("name").and_then(|n| n.as_str()) == Some("skirt"));
    assert_eq!(garments.len(), 1, "the sample manifest has a skirt");
    let skirt = garments[0].as_table_mut().unwrap();
    skirt.remove("dynamic");
    let recipe = skirt.get_mut("static").and_then(|r| r.as_table_mut());
    let recipe = recipe.expect("the skirt's static recipe");
    recipe.insert("epochs".into(), 1.into());
    recipe.remove("cache");
    recipe.insert("clips".into(), toml::Value::Array(vec!["131_02".into()]));
    toml::to_string(&m).unwrap()
}

/// A scratch folder that looks like the repository root to the pages' commands.
fn scratch(name: &str) -> PathBuf {
    let dir = out_dir(name);
    let samples = dir.join("samples");
    std::fs::create_dir_all(&samples).unwrap();
    for entry in std::fs::read_dir(root().join("samples")).unwrap() {
        let entry = entry.unwrap();
        let file = entry.file_name();
        if file.to_string_lossy().ends_with(".toml") {
            // Manifests: copied (their paths are relative to where they lie), the sample's cut.
            let text = std::fs::read_to_string(entry.path()).unwrap();
            let text = if file == "batch.toml" {
                short_manifest(&text)
            } else {
                text
            };
            std::fs::write(samples.join(&file), text).unwrap();
        } else {
            std::os::unix::fs::symlink(entry.path(), samples.join(&file)).unwrap();
        }
    }
    for made in ["out", "runs"] {
        std::fs::create_dir_all(dir.join(made)).unwrap();
    }
    dir
}

/// The pages run, each by one test: (page, its scratch folder, the ```sh blocks run, at least how
/// many commands they hold). A page's blocks may be split where a later block does not read an
/// earlier one's files (the dynamic guide's swing trains its own PBNS), so two tests run them
/// side by side.
const RUNS: [(&str, &str, Range<usize>, usize); 5] = [
    ("README.md", "docs_readme", 0..usize::MAX, 5),
    (
        "docs/guide/bake-a-garment.md",
        "docs_bake",
        0..usize::MAX,
        8,
    ),
    ("docs/guide/dynamic-garments.md", "docs_dynamic", 0..2, 8),
    (
        "docs/guide/dynamic-garments.md",
        "docs_swing",
        2..usize::MAX,
        5,
    ),
    ("docs/guide/batch.md", "docs_batch", 0..usize::MAX, 3),
];

/// Runs the commands of `RUNS[run]` in its scratch folder; returns how many ran.
fn run_page(run: usize) -> usize {
    let (page, scratch_name, blocks, at_least) = RUNS[run].clone();
    let dir = scratch(scratch_name);
    let steps: Vec<Step> = steps(page)
        .into_iter()
        .filter(|(b, _)| blocks.contains(b))
        .map(|(_, step)| step)
        .collect();
    eprintln!("{page}, with the short settings ({SHORT_SETTINGS}):");
    let mut ran = 0;
    let started = Instant::now();
    for step in steps {
        match step {
            Step::Mkdir(dirs) => dirs
                .iter()
                .for_each(|d| std::fs::create_dir_all(dir.join(d)).unwrap()),
            Step::Run {
                at,
                mut args,
                stdout_to,
            } => {
                shorten(&mut args);
                let t = Instant::now();
                let out = Command::new(env!("CARGO_BIN_EXE_garmentbake"))
                    .current_dir(&dir)
                    .args(&args)
                    .output()
                    .expect("run garmentbake");
                assert!(
                    out.status.success(),
                    "{at}: `garmentbake {}` failed ({}): {}",
                    args.join(" "),
                    out.status,
                    String::from_utf8_lossy(&out.stderr)
                );
                if let Some(file) = stdout_to {
                    std::fs::write(dir.join(file), &out.stdout).unwrap();
                }
                if let Some(i) = args.iter().position(|a| a == "--out") {
                    let written = dir.join(&args[i + 1]);
                    assert!(written.exists(), "{at}: {} not written", written.display());
                }
                eprintln!(
                    "{at}: {:.1} s: garmentbake {}",
                    t.elapsed().as_secs_f64(),
                    args.join(" ")
                );
                ran += 1;
            }
        }
    }
    eprintln!(
        "{page}: {ran} commands in {:.1} s",
        started.elapsed().as_secs_f64()
    );
    assert!(
        ran >= at_least,
        "{page}: {ran} commands found, at least {at_least} documented"
    );
    ran
}

#[test]
fn the_readme_commands_run_as_written() {
    run_page(0);
}

#[test]
fn the_bake_guide_runs_as_written() {
    run_page(1);
}

#[test]
fn the_dynamic_guide_runs_as_written() {
    run_page(2);
}

#[test]
fn the_dynamic_guides_swing_runs_as_written() {
    run_page(3);
}

#[test]
fn the_batch_guide_runs_as_written() {
    run_page(4);
}

/// Every block with commands of README.md and of every guide is run by one of [`RUNS`].
#[test]
fn every_documented_command_is_run() {
    let mut pages = vec!["README.md".to_string()];
    for entry in std::fs::read_dir(root().join("docs/guide")).unwrap() {
        let name = entry.unwrap().file_name().to_string_lossy().into_owned();
        if name.ends_with(".md") {
            pages.push(format!("docs/guide/{name}"));
        }
    }
    for page in pages {
        for (block, step) in steps(&page) {
            let run = RUNS
                .iter()
                .any(|(p, _, blocks, _)| *p == page && blocks.contains(&block));
            assert!(run, "{page}, sh block {block}: {step:?} is run by no test");
        }
    }
}

/// The extraction itself, on a made-up block: continuations, comments, `> FILE`, `$gb`,
/// `mkdir -p`, other programs skipped; and the short settings.
#[test]
fn commands_are_extracted_and_shortened() {
    let dir = out_dir("docs_extract");
    let page = dir.join("page.md");
    std::fs::write(
        &page,
        "text `garmentbake not-run`\n```sh\ngb=target/release/garmentbake  # the binary\nmkdir -p out\n\
         $gb train --motion a.bvh \\\n    --epochs 30 --out 'o ut/m.safetensors'   # trains\n\
         bash scripts/x.sh\ngarmentbake simulate --frames 60 --fps 30 --json > out/s.json\n```\n\
         ```\ngarmentbake not-sh\n```\n",
    )
    .unwrap();
    let rel = page
        .strip_prefix(root())
        .unwrap()
        .to_string_lossy()
        .into_owned();
    let (blocks, steps): (Vec<usize>, Vec<Step>) = steps(&rel).into_iter().unzip();
    assert_eq!(blocks, [0, 0, 0], "{steps:?}");
    assert!(matches!(&steps[0], Step::Mkdir(d) if d == &["out"]));
    let Step::Run {
        args, stdout_to, ..
    } = &steps[1]
    else {
        panic!()
    };
    assert_eq!(
        args.join(" "),
        "train --motion a.bvh --epochs 30 --out o ut/m.safetensors"
    );
    assert!(stdout_to.is_none());
    let mut short = args.clone();
    shorten(&mut short);
    assert_eq!(
        short.join(" "),
        "train --motion a.bvh --epochs 1 --out o ut/m.safetensors --fps 1"
    );
    let Step::Run {
        args, stdout_to, ..
    } = &steps[2]
    else {
        panic!()
    };
    assert_eq!(stdout_to.as_deref(), Some("out/s.json"));
    let mut short = args.clone();
    shorten(&mut short);
    assert_eq!(
        short.join(" "),
        format!(
            "simulate --frames 6 --fps 30 --json --settle 0.1 --blend 0.2 --cache {}",
            sim_cache()
        )
    );
    // The motion stage: the learnt dynamics (on by default) cut to fit six frames; off stays off.
    let words = |s: &str| s.split(' ').map(String::from).collect::<Vec<_>>();
    let mut stage = words("train-dynamic --stage dynamic --epochs 0 --out m.safetensors");
    shorten(&mut stage);
    assert_eq!(
        stage.join(" "),
        "train-dynamic --stage dynamic --epochs 0 --out m.safetensors --dynamics-epochs 1 --unroll-frames 2,3"
    );
    let mut off = words("train-dynamic --stage dynamic --dynamics-epochs 0");
    shorten(&mut off);
    assert_eq!(
        off.join(" "),
        "train-dynamic --stage dynamic --dynamics-epochs 0"
    );
}

/// docs/reference/commands.md says what the binary says: each section's text is the `--help` of
/// its command as this build prints it, and every command has a section. After changing a flag
/// or its help, rewrite the page with `bash scripts/reference_commands.sh`.
#[test]
fn the_command_reference_is_the_binarys_help() {
    let help = |command: &[&str]| {
        let out = Command::new(env!("CARGO_BIN_EXE_garmentbake"))
            .args(command)
            .arg("--help")
            .env("COLUMNS", "100")
            .output()
            .expect("run garmentbake");
        assert!(out.status.success(), "garmentbake {command:?} --help");
        String::from_utf8_lossy(&out.stdout)
            .lines()
            .map(|l| l.trim_end().to_string())
            .collect::<Vec<String>>()
    };
    let page = std::fs::read_to_string(root().join("docs/reference/commands.md")).unwrap();
    let mut documented = Vec::new();
    let mut lines = page.lines();
    while let Some(line) = lines.next() {
        let Some(command) = line
            .strip_prefix("## `garmentbake")
            .and_then(|c| c.strip_suffix('`'))
        else {
            continue;
        };
        assert_eq!(lines.next(), Some(""), "{line}");
        assert_eq!(lines.next(), Some("```text"), "{line}");
        let text: Vec<&str> = lines.by_ref().take_while(|l| *l != "```").collect();
        let words: Vec<&str> = command.split_whitespace().collect();
        let printed = help(&words);
        if let Some(i) = (0..text.len().max(printed.len()))
            .find(|&i| text.get(i).copied() != printed.get(i).map(String::as_str))
        {
            panic!(
                "docs/reference/commands.md: `garmentbake{command} --help` differs from the \
                 page at its line {}: page {:?}, binary {:?}; run bash \
                 scripts/reference_commands.sh",
                i + 1,
                text.get(i),
                printed.get(i)
            );
        }
        documented.push(command.trim().to_string());
    }
    // The commands `garmentbake --help` lists (two spaces, a name), each with a section of its
    // own or of its subcommands.
    let listed = help(&[]);
    let names = listed
        .iter()
        .skip_while(|l| *l != "Commands:")
        .skip(1)
        .take_while(|l| !l.is_empty())
        .filter_map(|l| l.strip_prefix("  ").filter(|n| !n.starts_with(' ')))
        .filter_map(|l| l.split_whitespace().next())
        .filter(|n| *n != "help");
    let mut commands = 0;
    for name in names {
        commands += 1;
        assert!(
            documented
                .iter()
                .any(|d| d == name || d.starts_with(&format!("{name} "))),
            "docs/reference/commands.md has no section for `garmentbake {name}`: run bash \
             scripts/reference_commands.sh"
        );
    }
    assert!(commands >= 15, "{commands} commands listed by --help");
}
