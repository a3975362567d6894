//! The memory budget: work whose size follows from its input (a raster's
//! declared size, a target grid, an image) is estimated before anything is
//! allocated, and refused with the size, the budget and the option to
//! change when it would not fit — an allocation failure must never reach
//! the allocator's abort. The budget defaults to the memory the machine has
//! available; `--max-memory` sets it. Either way it never exceeds what the
//! process may still take under its own limits: the address-space limit
//! (`ulimit -v`) less what it has mapped, its cgroup's limit (v2
//! `memory.max`, v1 `memory.limit_in_bytes`; a container's or a batch
//! job's) less what the cgroup uses, and the memory a Slurm job was given
//! (`SLURM_MEM_PER_NODE`, or `SLURM_MEM_PER_CPU` times its CPUs), for
//! clusters that do not enforce it with a cgroup.

use crate::{Error, Result};
use std::path::Path;
use std::sync::atomic::{AtomicU64, Ordering};

/// The budget in bytes; 0 until set or first read.
static BUDGET: AtomicU64 = AtomicU64::new(0);

/// Budget used where the machine's available memory cannot be read.
const FALLBACK_BYTES: u64 = 4 << 30;

/// Set the budget for this process, bytes (lowered to the process's limits).
pub fn set_budget(bytes: u64) {
    BUDGET.store(bytes.min(process_headroom()).max(1), Ordering::Relaxed);
}

/// The budget: as set, else the machine's available memory (Linux's
/// `MemAvailable`), else 4 GiB — in each case at most the process's
/// headroom under its limits.
pub fn budget() -> u64 {
    match BUDGET.load(Ordering::Relaxed) {
        0 => {
            let bytes = available_bytes()
                .unwrap_or(FALLBACK_BYTES)
                .min(process_headroom())
                .max(1);
            BUDGET.store(bytes, Ordering::Relaxed);
            bytes
        }
        b => b,
    }
}

/// `MemAvailable` from `/proc/meminfo`, bytes.
fn available_bytes() -> Option<u64> {
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    kib_field(&text, "MemAvailable:")
}

/// What this process may still allocate under its address-space limit, its
/// cgroup's memory limit and its Slurm allocation, bytes (`u64::MAX` where
/// none is set).
fn process_headroom() -> u64 {
    let address_space = std::fs::read_to_string("/proc/self/limits")
        .ok()
        .and_then(|limits| address_space_limit(&limits))
        .map_or(u64::MAX, |limit| {
            let mapped = std::fs::read_to_string("/proc/self/status")
                .ok()
                .and_then(|status| kib_field(&status, "VmSize:"))
                .unwrap_or(0);
            limit.saturating_sub(mapped)
        });
    let cgroup = std::fs::read_to_string("/proc/self/cgroup")
        .ok()
        .and_then(|text| cgroup_headroom(&text, Path::new("/sys/fs/cgroup")))
        .unwrap_or(u64::MAX);
    let slurm = slurm_allocation(|name| std::env::var(name).ok()).unwrap_or(u64::MAX);
    address_space.min(cgroup).min(slurm)
}

/// The memory a Slurm job step was given, bytes: `SLURM_MEM_PER_NODE`
/// (MB), else `SLURM_MEM_PER_CPU` (MB) times the CPUs of the task
/// (`SLURM_CPUS_PER_TASK`, else `SLURM_CPUS_ON_NODE`, else one); `None`
/// outside Slurm or where the job has no memory limit (0).
fn slurm_allocation(var: impl Fn(&str) -> Option<String>) -> Option<u64> {
    let number = |name: &str| var(name).and_then(|v| v.trim().parse::<u64>().ok());
    let mb = match number("SLURM_MEM_PER_NODE") {
        Some(mb) => mb,
        None => {
            let cpus = number("SLURM_CPUS_PER_TASK")
                .or_else(|| number("SLURM_CPUS_ON_NODE"))
                .unwrap_or(1);
            number("SLURM_MEM_PER_CPU")?.saturating_mul(cpus.max(1))
        }
    };
    (mb > 0).then(|| mb.saturating_mul(1 << 20))
}

/// The soft "Max address space" of `/proc/self/limits`, bytes; `None` when
/// unlimited.
fn address_space_limit(limits: &str) -> Option<u64> {
    let line = limits
        .lines()
        .find(|l| l.starts_with("Max address space"))?;
    line["Max address space".len()..]
        .split_whitespace()
        .next()?
        .parse()
        .ok()
}

/// The least headroom (limit − use) over the process's memory cgroup and
/// every cgroup above it, under `root`: cgroup v2's folder named in
/// `/proc/self/cgroup` (`0::/PATH`; `memory.max`, `memory.current`), else
/// cgroup v1's memory controller (`N:memory:/PATH` under `root/memory`;
/// `memory.limit_in_bytes`, `memory.usage_in_bytes`, where a limit near
/// 2⁶³ means none). `None` when no level sets a limit.
fn cgroup_headroom(proc_cgroup: &str, root: &Path) -> Option<u64> {
    let v2 = proc_cgroup.lines().find_map(|l| l.strip_prefix("0::"));
    let v1 = || {
        proc_cgroup.lines().find_map(|l| {
            let mut fields = l.splitn(3, ':');
            let (_, controllers, path) = (fields.next()?, fields.next()?, fields.next()?);
            controllers
                .split(',')
                .any(|c| c == "memory")
                .then_some(path)
        })
    };
    let (top, relative, [limit_file, usage_file]) = match v2 {
        Some(path) => (root.to_path_buf(), path, ["memory.max", "memory.current"]),
        None => (
            root.join("memory"),
            v1()?,
            ["memory.limit_in_bytes", "memory.usage_in_bytes"],
        ),
    };
    let mut dir = top.join(relative.trim_start_matches('/'));
    let mut least: Option<u64> = None;
    while dir.starts_with(&top) {
        let read = |name: &str| std::fs::read_to_string(dir.join(name)).ok();
        // cgroup v1 writes "no limit" as the largest page-aligned i64.
        let limit = read(limit_file)
            .and_then(|t| t.trim().parse::<u64>().ok())
            .filter(|&l| l < 1 << 62);
        if let Some(limit) = limit {
            let used = read(usage_file)
                .and_then(|t| t.trim().parse::<u64>().ok())
                .unwrap_or(0);
            least = Some(least.unwrap_or(u64::MAX).min(limit.saturating_sub(used)));
        }
        if !dir.pop() {
            break;
        }
    }
    least
}

/// A `NAME: VALUE kB` field of a /proc file, bytes.
fn kib_field(text: &str, name: &str) -> Option<u64> {
    let line = text.lines().find(|l| l.starts_with(name))?;
    let kib: u64 = line[name.len()..].split_whitespace().next()?.parse().ok()?;
    Some(kib.saturating_mul(1024))
}

/// Refuse `what` when it needs more than the budget: `count` items of
/// `item_bytes` each (saturating, so absurd sizes are refused, not
/// wrapped). `change` says which option or input would make it smaller.
pub fn check(what: &str, count: u64, item_bytes: u64, change: &str) -> Result<()> {
    let needed = count.saturating_mul(item_bytes);
    let limit = budget();
    if needed > limit {
        return Err(Error::Input(format!(
            "{what} needs about {} but the memory budget is {} \
             (raise it with --max-memory, or {change})",
            human(needed),
            human(limit)
        )));
    }
    Ok(())
}

/// Parse a size such as `512M`, `4G`, `1.5G` or a plain number of bytes
/// (K, M, G, T are powers of 1024).
pub fn parse_size(text: &str) -> std::result::Result<u64, String> {
    let t = text.trim();
    let (number, unit) = match t.char_indices().find(|(_, c)| c.is_ascii_alphabetic()) {
        Some((i, _)) => (&t[..i], &t[i..]),
        None => (t, ""),
    };
    let scale: u64 = match unit.to_ascii_uppercase().trim_end_matches(['B', 'I']) {
        "" => 1,
        "K" => 1 << 10,
        "M" => 1 << 20,
        "G" => 1 << 30,
        "T" => 1 << 40,
        _ => return Err(format!("{text:?}: expected a size such as 512M or 4G")),
    };
    let value: f64 = number
        .trim()
        .parse()
        .map_err(|_| format!("{text:?}: expected a size such as 512M or 4G"))?;
    if !(value.is_finite() && value > 0.0) {
        return Err(format!("{text:?}: the size must be positive"));
    }
    Ok((value * scale as f64).min(u64::MAX as f64) as u64)
}

/// Bytes in the largest binary unit that keeps a number ≥ 1.
pub fn human(bytes: u64) -> String {
    let units = ["B", "KiB", "MiB", "GiB", "TiB", "PiB", "EiB"];
    let mut value = bytes as f64;
    let mut unit = 0;
    while value >= 1024.0 && unit + 1 < units.len() {
        value /= 1024.0;
        unit += 1;
    }
    if unit == 0 {
        format!("{bytes} B")
    } else {
        format!("{value:.1} {}", units[unit])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_parse_and_print() {
        assert_eq!(parse_size("512M"), Ok(512 << 20));
        assert_eq!(parse_size("4G"), Ok(4 << 30));
        assert_eq!(parse_size("1.5GiB"), Ok(3 << 29));
        assert_eq!(parse_size("1000"), Ok(1000));
        assert!(parse_size("-1G").is_err() && parse_size("lots").is_err());
        assert!(parse_size("4X").is_err() && parse_size("nanG").is_err());
        assert_eq!(human(3 << 29), "1.5 GiB");
        assert_eq!(human(12), "12 B");
    }

    #[test]
    fn work_over_the_budget_is_refused_with_the_sizes() {
        set_budget(1 << 30);
        assert!(check("a grid", 1 << 20, 8, "crop it").is_ok());
        let message = check("a 300000×300000 grid", 300_000 * 300_000, 8, "pass --te")
            .unwrap_err()
            .to_string();
        assert!(
            message.contains("670.6 GiB")
                && message.contains("1.0 GiB")
                && message.contains("--max-memory")
                && message.contains("pass --te"),
            "{message}"
        );
        // Sizes beyond u64 saturate rather than wrap to something small.
        assert!(check("absurd", u64::MAX, 8, "no").is_err());
    }

    #[test]
    fn the_process_limits_are_read() {
        let limits = "Limit                     Soft Limit           Hard Limit           Units\n\
                      Max stack size            8388608              unlimited            bytes\n\
                      Max address space         6442450944           unlimited            bytes\n";
        assert_eq!(address_space_limit(limits), Some(6 << 30));
        assert_eq!(
            address_space_limit(&limits.replace("6442450944", "unlimited")),
            None
        );
        assert_eq!(kib_field("VmSize:\t  2048 kB\n", "VmSize:"), Some(2 << 20));

        // A job's cgroup at 3 GiB using 1 GiB, under a parent at 8 GiB.
        let root = tempfile::tempdir().unwrap();
        let job = root.path().join("slurm/job_7");
        std::fs::create_dir_all(&job).unwrap();
        std::fs::write(root.path().join("slurm/memory.max"), "8589934592\n").unwrap();
        std::fs::write(job.join("memory.max"), "3221225472\n").unwrap();
        std::fs::write(job.join("memory.current"), "1073741824\n").unwrap();
        let at = |text: &str| cgroup_headroom(text, root.path());
        assert_eq!(at("0::/slurm/job_7\n"), Some(2 << 30));
        std::fs::write(job.join("memory.max"), "max\n").unwrap();
        assert_eq!(at("0::/slurm/job_7\n"), Some(8 << 30));
        assert_eq!(at("1:name=systemd:/\n"), None);
        assert!(process_headroom() > 0);
    }

    #[test]
    fn cgroup_v1_and_slurm_allocations_bound_the_budget() {
        // cgroup v1: the job's memory controller at 2 GiB using 512 MiB,
        // its parent without a limit (v1's "none" value).
        let root = tempfile::tempdir().unwrap();
        let job = root.path().join("memory/slurm/uid_0/job_9");
        std::fs::create_dir_all(&job).unwrap();
        let parent = root.path().join("memory/slurm");
        std::fs::write(
            parent.join("memory.limit_in_bytes"),
            "9223372036854771712\n",
        )
        .unwrap();
        std::fs::write(job.join("memory.limit_in_bytes"), "2147483648\n").unwrap();
        std::fs::write(job.join("memory.usage_in_bytes"), "536870912\n").unwrap();
        let v1 = "12:pids:/slurm/uid_0/job_9\n4:cpuset,memory:/slurm/uid_0/job_9\n";
        assert_eq!(cgroup_headroom(v1, root.path()), Some(3 << 29));
        assert_eq!(cgroup_headroom("4:memory:/elsewhere\n", root.path()), None);

        // Slurm: --mem (per node) wins; --mem-per-cpu times the task's CPUs.
        let env = |pairs: &'static [(&'static str, &'static str)]| {
            move |name: &str| {
                pairs
                    .iter()
                    .find(|(k, _)| *k == name)
                    .map(|(_, v)| v.to_string())
            }
        };
        assert_eq!(
            slurm_allocation(env(&[("SLURM_MEM_PER_NODE", "4000")])),
            Some(4000 << 20)
        );
        assert_eq!(
            slurm_allocation(env(&[
                ("SLURM_MEM_PER_CPU", "1500"),
                ("SLURM_CPUS_PER_TASK", "4")
            ])),
            Some(6000 << 20)
        );
        assert_eq!(
            slurm_allocation(env(&[
                ("SLURM_MEM_PER_CPU", "1500"),
                ("SLURM_CPUS_ON_NODE", "2")
            ])),
            Some(3000 << 20)
        );
        assert_eq!(slurm_allocation(env(&[("SLURM_MEM_PER_NODE", "0")])), None);
        assert_eq!(slurm_allocation(env(&[])), None);
    }
}
