//! The README's tour runs as written: every `lamina` line of its first `sh` block after
//! "A short tour", in a fresh folder holding a copy of `pipelines/`, in order (later
//! lines read what earlier ones wrote), each succeeding.

use crate::support::{copy_dir, lamina_in, root, text};

/// The tour's command lines, comments removed, split into words.
fn tour() -> Vec<Vec<String>> {
    let readme = std::fs::read_to_string(root().join("README.md")).expect("README.md");
    let start = readme.find("## A short tour").expect("a tour in the README");
    let block = &readme[start..];
    let open = block.find("```sh\n").expect("an sh block in the tour") + "```sh\n".len();
    let close = block[open..].find("```").expect("the block closes") + open;
    block[open..close]
        .lines()
        .map(|l| l.split(" #").next().unwrap_or_default().trim())
        .filter(|l| !l.is_empty())
        .map(|l| l.split_whitespace().map(str::to_string).collect())
        .collect()
}

#[test]
fn every_command_of_the_readme_tour_runs_as_written() {
    let lines = tour();
    assert!(lines.len() >= 10, "the tour lost its commands: {lines:?}");
    let dir = tempfile::tempdir().expect("tempdir");
    copy_dir(&root().join("pipelines"), &dir.path().join("pipelines"));
    for words in &lines {
        assert_eq!(
            words[0], "lamina",
            "a tour line that is not a lamina command: {words:?}"
        );
        let args: Vec<&str> = words[1..].iter().map(String::as_str).collect();
        let out = lamina_in(dir.path(), &args);
        assert!(
            out.status.success(),
            "`{}` failed:\n{}{}",
            words.join(" "),
            text(&out.stdout),
            text(&out.stderr)
        );
    }
    // What the tour says it writes.
    for made in ["blade.stl", "assembly.3mf", "cube.obj", "my-grader/Cargo.toml"] {
        assert!(dir.path().join(made).is_file(), "the tour did not write {made}");
    }
}
