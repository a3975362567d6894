//! A single-node Slurm cluster in a folder, for the cluster test and the
//! cluster benchmark: munged on its own socket, slurmctld and slurmd on
//! free ports, the node's 2 CPUs and 2000 MB; stopped when dropped. Needs
//! Debian's slurmctld, slurmd, slurm-client and munge (scripts/setup-test)
//! and the right to run them as the current user. One file, included by
//! path where it is used.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::{Duration, Instant};

pub struct Cluster {
    dir: PathBuf,
    conf: PathBuf,
    socket: PathBuf,
}

fn free_port() -> Result<u16, String> {
    std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .map(|a| a.port())
        .map_err(|e| format!("no free port: {e}"))
}

/// Run `cmd`; its output when it succeeds.
pub fn run(cmd: &mut Command) -> Result<Output, String> {
    let out = cmd
        .output()
        .map_err(|e| format!("{cmd:?}: {e} (Slurm and munge come from scripts/setup-test)"))?;
    if !out.status.success() {
        return Err(format!(
            "{cmd:?}: {}{}",
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        ));
    }
    Ok(out)
}

fn text(out: Output) -> String {
    String::from_utf8_lossy(&out.stdout).trim().to_string()
}

impl Cluster {
    /// Configure and start a cluster in `dir` (an empty folder), and wait
    /// until its node is idle.
    pub fn start(dir: &Path) -> Result<Cluster, String> {
        use std::os::unix::fs::PermissionsExt;
        let io = |e: std::io::Error| format!("{}: {e}", dir.display());
        for sub in ["munge", "state", "spool", "log"] {
            std::fs::create_dir_all(dir.join(sub)).map_err(io)?;
        }
        let key = dir.join("munge/munge.key");
        let mut bytes = vec![0u8; 1024];
        std::io::Read::read_exact(
            &mut std::fs::File::open("/dev/urandom").map_err(io)?,
            &mut bytes,
        )
        .map_err(io)?;
        std::fs::write(&key, bytes).map_err(io)?;
        std::fs::set_permissions(&key, std::fs::Permissions::from_mode(0o400)).map_err(io)?;
        std::fs::set_permissions(dir.join("munge"), std::fs::Permissions::from_mode(0o711))
            .map_err(io)?;
        let socket = dir.join("munge/socket");
        run(Command::new("munged")
            .arg("--force")
            .arg(format!("--socket={}", socket.display()))
            .arg(format!("--key-file={}", key.display()))
            .arg(format!(
                "--log-file={}",
                dir.join("log/munged.log").display()
            ))
            .arg(format!(
                "--pid-file={}",
                dir.join("munge/munged.pid").display()
            ))
            .arg(format!("--seed-file={}", dir.join("munge/seed").display())))?;
        let host = text(run(Command::new("hostname").arg("-s"))?);
        let user = text(run(&mut Command::new("whoami"))?);
        let d = dir.display();
        let conf = dir.join("slurm.conf");
        let config = format!(
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
            ctld = free_port()?,
            slurmd = free_port()?,
        );
        std::fs::write(&conf, config).map_err(io)?;
        let cluster = Cluster {
            dir: dir.to_path_buf(),
            conf,
            socket,
        };
        run(cluster.command("slurmctld").arg("-f").arg(&cluster.conf))?;
        run(cluster.command("slurmd").arg("-f").arg(&cluster.conf))?;
        let start = Instant::now();
        loop {
            let out = cluster.command("sinfo").args(["-h", "-o", "%t"]).output();
            if out.is_ok_and(|o| String::from_utf8_lossy(&o.stdout).trim() == "idle") {
                return Ok(cluster);
            }
            if start.elapsed() > Duration::from_secs(60) {
                return Err(format!(
                    "the cluster did not come up: {}",
                    std::fs::read_to_string(dir.join("log/slurmctld.log")).unwrap_or_default()
                ));
            }
            std::thread::sleep(Duration::from_millis(200));
        }
    }

    /// `program` talking to this cluster (`SLURM_CONF` set).
    pub fn command(&self, program: impl AsRef<std::ffi::OsStr>) -> Command {
        let mut c = Command::new(program);
        c.env("SLURM_CONF", &self.conf);
        c
    }

    /// Wait until the queue is empty, at most `limit`.
    pub fn drain(&self, limit: Duration) -> Result<(), String> {
        let start = Instant::now();
        loop {
            let queue = text(run(self.command("squeue").args(["-h", "-o", "%i %T %r"]))?);
            if queue.is_empty() {
                return Ok(());
            }
            if start.elapsed() > limit {
                return Err(format!("the jobs did not finish: {queue}"));
            }
            std::thread::sleep(Duration::from_millis(250));
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
        // Let the daemons leave before their folder goes.
        let alive = |f: &str| {
            std::fs::read_to_string(self.dir.join(f))
                .is_ok_and(|p| Path::new(&format!("/proc/{}", p.trim())).exists())
        };
        let start = Instant::now();
        while (alive("slurmctld.pid") || alive("slurmd.pid"))
            && start.elapsed() < Duration::from_secs(20)
        {
            std::thread::sleep(Duration::from_millis(200));
        }
    }
}
