//! `relevo prep --plan DIR --submit slurm` on a real Slurm (Debian's
//! slurm-wlm and munge, installed by scripts/setup-test): a single-node
//! cluster this test configures, starts and stops. The plan of the real
//! Grenoble DEM (warped to UTM, holes filled window by window) runs as
//! array jobs chained by `afterok` and gives the bytes of `relevo prep
//! --tiled` on one machine; each task runs inside the memory Slurm gives
//! it; a second submission while the first is queued is refused; a
//! cancelled task leaves the plan incomplete, `--finish` names what is
//! missing, and submitting again sends only that and completes the same
//! bytes.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod common;

use common::{projected_dem_named, relevo_ok, set_cells, sha256};
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::{Duration, Instant};

/// A single-node Slurm cluster in a temporary folder: munged on its own
/// socket, slurmctld and slurmd on free ports; stopped when dropped.
struct Cluster {
    dir: tempfile::TempDir,
    conf: PathBuf,
    socket: PathBuf,
}

fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

fn run(cmd: &mut Command) -> Output {
    let out = cmd
        .output()
        .unwrap_or_else(|e| panic!("{cmd:?}: {e} (Slurm and munge come from scripts/setup-test)"));
    assert!(
        out.status.success(),
        "{cmd:?}: {}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

impl Cluster {
    fn start() -> Cluster {
        let dir = tempfile::tempdir().unwrap();
        let p = |s: &str| dir.path().join(s);
        for sub in ["munge", "state", "spool", "log"] {
            std::fs::create_dir(p(sub)).unwrap();
        }
        use std::os::unix::fs::PermissionsExt;
        let key = p("munge/munge.key");
        let bytes: Vec<u8> = (0..1024u32).map(|i| (i * 2654435761 >> 13) as u8).collect();
        std::fs::write(&key, bytes).unwrap();
        std::fs::set_permissions(&key, std::fs::Permissions::from_mode(0o400)).unwrap();
        std::fs::set_permissions(p("munge"), std::fs::Permissions::from_mode(0o711)).unwrap();
        let socket = p("munge/socket");
        run(Command::new("munged")
            .arg("--force")
            .arg(format!("--socket={}", socket.display()))
            .arg(format!("--key-file={}", key.display()))
            .arg(format!("--log-file={}", p("log/munged.log").display()))
            .arg(format!("--pid-file={}", p("munge/munged.pid").display()))
            .arg(format!("--seed-file={}", p("munge/seed").display())));
        let host = String::from_utf8(run(Command::new("hostname").arg("-s")).stdout)
            .unwrap()
            .trim()
            .to_string();
        let user = String::from_utf8(run(&mut Command::new("whoami")).stdout)
            .unwrap()
            .trim()
            .to_string();
        let d = dir.path().display();
        let conf = p("slurm.conf");
        let text = format!(
            "ClusterName=relevo-test\n\
             SlurmctldHost={host}(127.0.0.1)\n\
             SlurmUser={user}\nSlurmdUser={user}\n\
             AuthType=auth/munge\nCredType=cred/munge\nAuthInfo=socket={socket}\n\
             SlurmctldPort={ctld}\nSlurmdPort={slurmd}\n\
             StateSaveLocation={d}/state\nSlurmdSpoolDir={d}/spool\n\
             SlurmctldPidFile={d}/slurmctld.pid\nSlurmdPidFile={d}/slurmd.pid\n\
             SlurmctldLogFile={d}/log/slurmctld.log\nSlurmdLogFile={d}/log/slurmd.log\n\
             ProctrackType=proctrack/pgid\nTaskPlugin=task/none\n\
             SelectType=select/cons_tres\nSelectTypeParameters=CR_Core_Memory\n\
             SchedulerType=sched/builtin\nDependencyParameters=kill_invalid_depend\n\
             MpiDefault=none\nReturnToService=2\n\
             JobCompType=jobcomp/none\nAccountingStorageType=accounting_storage/none\n\
             JobAcctGatherType=jobacct_gather/none\n\
             NodeName={host} NodeAddr=127.0.0.1 CPUs=2 RealMemory=2000 State=UNKNOWN\n\
             PartitionName=test Nodes={host} Default=YES MaxTime=INFINITE State=UP\n",
            socket = socket.display(),
            ctld = free_port(),
            slurmd = free_port(),
        );
        std::fs::write(&conf, text).unwrap();
        let cluster = Cluster { dir, conf, socket };
        run(cluster.command("slurmctld").arg("-f").arg(&cluster.conf));
        run(cluster.command("slurmd").arg("-f").arg(&cluster.conf));
        // Up when the node is idle.
        let start = Instant::now();
        loop {
            let out = cluster.command("sinfo").args(["-h", "-o", "%t"]).output();
            if out.is_ok_and(|o| String::from_utf8_lossy(&o.stdout).trim() == "idle") {
                break;
            }
            assert!(
                start.elapsed() < Duration::from_secs(60),
                "the test cluster did not come up: {}",
                std::fs::read_to_string(cluster.dir.path().join("log/slurmctld.log"))
                    .unwrap_or_default()
            );
            std::thread::sleep(Duration::from_millis(200));
        }
        cluster
    }

    /// `program` talking to this cluster.
    fn command(&self, program: &str) -> Command {
        let mut c = Command::new(program);
        c.env("SLURM_CONF", &self.conf);
        c
    }

    /// `relevo ARGS…` talking to this cluster.
    fn relevo(&self, args: &[&str]) -> Output {
        let mut c = self.command(env!("CARGO_BIN_EXE_relevo"));
        c.args(args).output().unwrap()
    }

    /// Wait until the queue is empty.
    fn drain(&self) {
        let start = Instant::now();
        loop {
            let out = run(self.command("squeue").args(["-h", "-o", "%i %T %r"]));
            let queue = String::from_utf8_lossy(&out.stdout).to_string();
            if queue.trim().is_empty() {
                return;
            }
            assert!(
                start.elapsed() < Duration::from_secs(240),
                "the jobs did not finish: {queue}"
            );
            std::thread::sleep(Duration::from_millis(500));
        }
    }
}

impl Drop for Cluster {
    fn drop(&mut self) {
        let _ = self.command("scontrol").arg("shutdown").output();
        let _ = Command::new("munged")
            .arg("--stop")
            .arg(format!("--socket={}", self.socket.display()))
            .output();
        // Give the daemons a moment to leave before their folder goes.
        let pid = |f: &str| std::fs::read_to_string(self.dir.path().join(f)).ok();
        let start = Instant::now();
        while ["slurmctld.pid", "slurmd.pid"]
            .iter()
            .any(|f| pid(f).is_some_and(|p| Path::new(&format!("/proc/{}", p.trim())).exists()))
            && start.elapsed() < Duration::from_secs(20)
        {
            std::thread::sleep(Duration::from_millis(200));
        }
    }
}

fn contents(p: &Path) -> (Vec<String>, serde_json::Value) {
    let tiles = ["height.f32", "mask.u8", "lp.f32x2", "drape.rgba8"]
        .iter()
        .map(|f| sha256(&p.join("tiles").join(f)))
        .collect();
    let mut manifest: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(p.join("manifest.json")).unwrap()).unwrap();
    manifest.as_object_mut().unwrap().remove("timings");
    (tiles, manifest)
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).to_string()
}

/// What `--submit slurm --json` printed: (step, plan jobs, Slurm job id).
fn submitted(o: &Output) -> Vec<(String, Vec<u64>, String)> {
    assert!(o.status.success(), "{}", stderr(o));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    v.as_array()
        .unwrap()
        .iter()
        .map(|s| {
            (
                s["step"].as_str().unwrap().to_string(),
                s["jobs"]
                    .as_array()
                    .unwrap()
                    .iter()
                    .map(|j| j.as_u64().unwrap())
                    .collect(),
                s["slurm_job_id"].as_str().unwrap().to_string(),
            )
        })
        .collect()
}

#[test]
fn a_plan_runs_as_slurm_array_jobs_to_the_single_machine_pyramid_and_survives_a_cancelled_task() {
    let d = tempfile::tempdir().unwrap();
    let dem = projected_dem_named(d.path(), "holes.tif", &["-dstnodata", "-32768"]);
    for cells in [[100, 120, 6, 4], [497, 300, 30, 2]] {
        set_cells(&dem, 32631, cells, -32768.0);
    }
    let dem = dem.to_str().unwrap().to_string();
    let local = d.path().join("local");
    std::fs::create_dir(&local).unwrap();
    let prep = ["prep", "--dem", &dem, "--tiled", "--tile-size", "256", "-q"];
    let out = local.join("g.relevo");
    relevo_ok([&prep[..], &["--out", out.to_str().unwrap()]].concat());
    let expected = contents(&out);

    let cluster = Cluster::start();
    // The whole plan, 4 jobs a step, 300 MB a task.
    let here = d.path().join("whole");
    std::fs::create_dir(&here).unwrap();
    let (plan, out) = (here.join("plan"), here.join("g.relevo"));
    let (plan_s, out_s) = (plan.to_str().unwrap(), out.to_str().unwrap());
    let o = cluster.relevo(
        &[
            &prep[..],
            &["--plan", plan_s, "--jobs", "4", "--out", out_s],
            &["--submit", "slurm", "--mem", "300M", "--json"],
        ]
        .concat(),
    );
    let ids = submitted(&o);
    let steps: Vec<&str> = ids.iter().map(|(s, _, _)| s.as_str()).collect();
    assert_eq!(
        steps,
        [
            "heights",
            "own errors",
            "errors and radii",
            "lattice",
            "drape",
            "level 1",
            "level 1 drape",
            "level 2",
            "level 2 drape",
            "finish"
        ]
    );
    // Submitting again while these are queued is refused, naming them.
    let again = cluster.relevo(&["prep", "--plan", plan_s, "--submit", "slurm"]);
    assert_eq!(again.status.code(), Some(1));
    assert!(
        stderr(&again).contains("still queued or running") && stderr(&again).contains("scancel"),
        "{}",
        stderr(&again)
    );
    cluster.drain();
    assert!(
        out.exists(),
        "the finish job did not move the pyramid into place: {:?}",
        std::fs::read_to_string(plan.join("logs/10-finish.log"))
    );
    assert_eq!(contents(&out), expected, "Slurm's pyramid differs");
    // Every task ran under Slurm with the memory it was given.
    for k in 0..=ids[8].1[0] {
        let record: serde_json::Value = serde_json::from_str(
            &std::fs::read_to_string(plan.join(format!("jobs/{k}.json"))).unwrap(),
        )
        .unwrap();
        assert!(record["slurm"].is_string(), "{record}");
        assert_eq!(record["memory_budget_bytes"], 300u64 << 20, "{record}");
    }

    // A task cancelled: the steps after it never run.
    let here = d.path().join("cancelled");
    std::fs::create_dir(&here).unwrap();
    let (plan, out) = (here.join("plan"), here.join("g.relevo"));
    let (plan_s, out_s) = (plan.to_str().unwrap(), out.to_str().unwrap());
    let o = cluster.relevo(
        &[
            &prep[..],
            &["--plan", plan_s, "--jobs", "4", "--out", out_s],
            &["--submit", "slurm", "--json"],
        ]
        .concat(),
    );
    let ids = submitted(&o);
    let (_, own_jobs, own_id) = &ids[1];
    run(cluster.command("scancel").arg(format!("{own_id}_2")));
    cluster.drain();
    assert!(!out.exists());
    let finish = cluster.relevo(&["prep", "--plan", plan_s, "--finish"]);
    let e = stderr(&finish);
    assert_eq!(finish.status.code(), Some(1), "{e}");
    let cancelled = own_jobs[2];
    assert!(
        e.contains(&format!("{cancelled} (own errors, 4 tiles)")) && e.contains("--submit slurm"),
        "{e}"
    );
    // Submitted again: only the cancelled job of its step, then the rest.
    let ids =
        submitted(&cluster.relevo(&["prep", "--plan", plan_s, "--submit", "slurm", "--json"]));
    assert_eq!(ids[0].0, "own errors");
    assert_eq!(ids[0].1, [cancelled]);
    cluster.drain();
    assert_eq!(
        contents(&out),
        expected,
        "the resubmitted plan's pyramid differs"
    );
}
