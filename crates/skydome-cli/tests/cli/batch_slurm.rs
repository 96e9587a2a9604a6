//! `skydome batch` on a real Slurm: `deploy/slurm/skydome-array.sbatch` submitted as a three-task
//! job array (`sbatch --array=0-2 --wait`), the parts collected, and the table compared with a
//! one-machine run. Needs a running cluster (`scripts/slurm-one-node.sh start`, which `.ci/run`
//! does); skips with a message when `sbatch` is absent, fails instead when
//! `SKYDOME_REQUIRE_SLURM=1`.

use std::path::Path;
use std::process::Command;

const BIN: &str = env!("CARGO_BIN_EXE_skydome");
use crate::SYNTH_DOME as DOME;

/// True when a Slurm cluster answers; otherwise the skip is reported through the shared guard
/// (a failure when `SKYDOME_REQUIRE_SLURM=1`, as in CI).
fn slurm_available() -> bool {
    let ok = Command::new("sinfo")
        .args(["-h", "-o", "%T"])
        .output()
        .is_ok_and(|o| o.status.success() && !o.stdout.is_empty());
    if !ok {
        crate::common::required::skip(
            "SKYDOME_REQUIRE_SLURM",
            "no running Slurm (sinfo/sbatch); start one with scripts/slurm-one-node.sh start",
        );
    }
    ok
}

fn run(c: &mut Command) -> String {
    let o = c.output().unwrap();
    let said = format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(o.status.success(), "{c:?}: {said}");
    said
}

#[test]
fn three_slurm_array_tasks_give_the_one_machine_table() {
    if !slurm_available() {
        return;
    }
    // Slurm's tasks run as the submitting user on this node and need paths they can read.
    let root = tempfile::tempdir().unwrap();
    let photos = root.path().join("photos");
    let one = root.path().join("one");
    let shared = root.path().join("shared");
    for d in [&photos, &one, &shared] {
        std::fs::create_dir(d).unwrap();
    }
    run(Command::new(BIN).args(["synth", "-o"]).arg(&photos).args([
        "--captures",
        "6",
        "--size",
        "128",
        "--gps",
        "47.37,8.54",
        "--quiet",
    ]));
    run(Command::new(BIN)
        .arg("batch")
        .arg(&photos)
        .arg("-o")
        .arg(&one)
        .args(DOME)
        .arg("--quiet")
        .env_remove("SLURM_ARRAY_TASK_ID"));

    let script =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../deploy/slurm/skydome-array.sbatch");
    let said = run(Command::new("sbatch")
        .args(["--array=0-2", "--wait", "--cpus-per-task=1", "--mem=0"])
        .arg(format!(
            "--output={}/slurm-%A_%a.out",
            root.path().display()
        ))
        .arg(format!("--chdir={}", root.path().display()))
        .arg(&script)
        .args(DOME)
        .env("SKYDOME", BIN)
        .env("INPUT", &photos)
        .env("OUT", &shared));
    assert!(said.contains("Submitted batch job"), "{said}");
    for i in 0..3 {
        assert!(
            shared.join(format!("parts/shard-{i}-of-3.jsonl")).is_file(),
            "task {i} wrote no part"
        );
    }
    run(Command::new(BIN)
        .args(["batch", "--collect"])
        .arg(&shared)
        .arg("--quiet"));
    let table = std::fs::read(one.join("captures.csv")).unwrap();
    assert_eq!(table, std::fs::read(shared.join("captures.csv")).unwrap());
    assert_eq!(
        std::fs::read(one.join("captures.jsonl")).unwrap(),
        std::fs::read(shared.join("captures.jsonl")).unwrap()
    );
    assert_eq!(String::from_utf8(table).unwrap().lines().count(), 7);
    // Every dome was made by exactly one task, byte-identical to the one-machine run's.
    for e in std::fs::read_dir(&one).unwrap() {
        let p = e.unwrap().path();
        if p.extension().is_some_and(|x| x == "hdr") {
            let name = p.file_name().unwrap();
            assert_eq!(
                std::fs::read(&p).unwrap(),
                std::fs::read(shared.join(name)).unwrap(),
                "{name:?}"
            );
        }
    }
}
