//! The memory budget of one job: a byte limit, the estimate of what a scene
//! will need checked against it before anything big is allocated, and the
//! size strings (`512M`, `8G`, `1.5GiB`) that set it.
//!
//! Loaders ask [`MemoryBudget::process`] before sizing anything by a count
//! read from a file (an image's width and height, an accessor's count); the
//! facade adds up a prepared scene's large consumers ([`Estimate`]) and
//! refuses the render with the largest of them named when the sum does not
//! fit. An allocation that fails aborts the process, which no error handler
//! can catch, so the checks come first.

use serde::{Deserialize, Deserializer, Serialize, Serializer};
use std::fmt;
use std::sync::OnceLock;
use std::sync::atomic::{AtomicU64, Ordering};

/// Used when the machine's memory cannot be read.
const FALLBACK_BYTES: u64 = 4 << 30;
/// The largest size accepted (1 EiB; it still fits a TOML integer).
const MAX_BYTES: u64 = 1 << 60;
/// The default never exceeds this, however large the machine.
const DEFAULT_CAP_BYTES: u64 = 256 << 30;

/// A number of bytes, written and read as a size string (`"512M"`) or an
/// integer in TOML, JSON and `--set`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct ByteSize(pub u64);

impl fmt::Display for ByteSize {
    /// Binary units with one decimal (`1.5 GiB`), bytes below 1 KiB.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        const UNITS: [&str; 5] = ["KiB", "MiB", "GiB", "TiB", "PiB"];
        let mut v = self.0 as f64;
        if v < 1024.0 {
            return write!(f, "{} B", self.0);
        }
        let mut unit = "B";
        for u in UNITS {
            if v < 1024.0 {
                break;
            }
            v /= 1024.0;
            unit = u;
        }
        write!(f, "{v:.1} {unit}")
    }
}

impl std::str::FromStr for ByteSize {
    type Err = String;

    /// Parses `123`, `64K`, `512M`, `8G`, `1T` (and `KB`/`KiB`, any case,
    /// optional space and decimals); every unit is a power of 1024.
    fn from_str(s: &str) -> Result<Self, String> {
        let t = s.trim();
        let split = t
            .find(|c: char| !(c.is_ascii_digit() || c == '.'))
            .unwrap_or(t.len());
        let (num, unit) = t.split_at(split);
        let shift = match unit.trim().to_ascii_lowercase().as_str() {
            "" | "b" => 0,
            "k" | "kb" | "kib" => 10,
            "m" | "mb" | "mib" => 20,
            "g" | "gb" | "gib" => 30,
            "t" | "tb" | "tib" => 40,
            _ => {
                return Err(format!(
                    "`{s}` is not a size (expected e.g. 512M, 8G, 1.5GiB)"
                ));
            }
        };
        let v: f64 = num
            .parse()
            .map_err(|_| format!("`{s}` is not a size (expected e.g. 512M, 8G, 1.5GiB)"))?;
        let bytes = v * (1u64 << shift) as f64;
        if !(1.0..=MAX_BYTES as f64).contains(&bytes) {
            return Err(format!("size `{s}` is out of range"));
        }
        Ok(Self(bytes as u64))
    }
}

impl Serialize for ByteSize {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_u64(self.0)
    }
}

impl<'de> Deserialize<'de> for ByteSize {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        #[derive(Deserialize)]
        #[serde(untagged)]
        enum Raw {
            Int(u64),
            Text(String),
        }
        match Raw::deserialize(d)? {
            Raw::Int(0) => Err(serde::de::Error::custom("a memory limit must be positive")),
            Raw::Int(n) if n > MAX_BYTES => {
                Err(serde::de::Error::custom("memory limit out of range"))
            }
            Raw::Int(n) => Ok(Self(n)),
            Raw::Text(s) => s.parse().map_err(serde::de::Error::custom),
        }
    }
}

/// How many bytes one job may allocate for its large data.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct MemoryBudget {
    /// The limit in bytes.
    pub limit: ByteSize,
}

/// The most a job's shadow maps take, however large its budget: past it,
/// building the maps costs more time than the shadow rays that replace them.
const SHADOW_MAP_CAP_BYTES: u64 = 512 << 20;

/// The process-wide limit set by [`MemoryBudget::set_process`]; 0 = not set.
static PROCESS_LIMIT: AtomicU64 = AtomicU64::new(0);

impl MemoryBudget {
    /// A budget of `bytes`.
    pub const fn new(bytes: u64) -> Self {
        Self {
            limit: ByteSize(bytes),
        }
    }

    /// [`DEFAULT_SHARE`] of the process's memory limit ([`SystemMemory`]:
    /// the smallest of `MemTotal`, the cgroup's limit and `RLIMIT_AS`), at
    /// most 256 GiB; 4 GiB where none can be read.
    pub fn machine_default() -> Self {
        static DEFAULT: OnceLock<u64> = OnceLock::new();
        Self::new(*DEFAULT.get_or_init(|| SystemMemory::read().default_budget()))
    }

    /// The budget that loaders use: the one set with [`Self::set_process`]
    /// (the CLI's `--memory-limit`), else [`Self::machine_default`].
    pub fn process() -> Self {
        match PROCESS_LIMIT.load(Ordering::Relaxed) {
            0 => Self::machine_default(),
            n => Self::new(n),
        }
    }

    /// Sets the budget that [`Self::process`] returns from now on.
    pub fn set_process(limit: ByteSize) {
        PROCESS_LIMIT.store(limit.0.max(1), Ordering::Relaxed);
    }

    /// The bytes a job's shadow maps may take: a quarter of the budget (the
    /// rest holds geometry, textures and films), at most 512 MiB. Lights
    /// whose maps do not fit use shadow rays (the documented cheaper path),
    /// so the estimate counts shadow maps only up to this.
    pub fn shadow_map_bytes(&self) -> u64 {
        (self.limit.0 / 4).min(SHADOW_MAP_CAP_BYTES)
    }

    /// `Ok` when `bytes` fit; otherwise a message naming `what`, its size and
    /// the limit.
    pub fn check(&self, what: &str, bytes: u64) -> Result<(), String> {
        if bytes <= self.limit.0 {
            Ok(())
        } else {
            Err(format!(
                "{what} needs {} but the memory limit is {} (set with --memory-limit or render.memory_limit)",
                ByteSize(bytes),
                self.limit
            ))
        }
    }
}

/// The share of the process's memory limit that the default budget takes.
/// The other half covers what the estimate does not count: a `Vec`'s spare
/// capacity and the copy made while it grows, the loaders' transient
/// buffers, and, under `RLIMIT_AS` (which counts address space, not
/// memory), the thread stacks and the allocator's arena reservations: a
/// gouraud or path render of a 2M-triangle plane on 2 threads peaked
/// 250-300 MiB of address space above its resident peak (`VmPeak` against
/// `VmHWM`), well inside this half of a 4 GB limit (decision 0036).
pub const DEFAULT_SHARE: f64 = 0.5;

/// A cgroup v1 `memory.limit_in_bytes` at or above this means "no limit"
/// (the kernel writes 2^63 rounded down to a page).
const CGROUP_V1_UNLIMITED: u64 = 1 << 60;

/// Which reading set the process's memory limit.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LimitSource {
    /// `MemTotal` of `/proc/meminfo`.
    MemTotal,
    /// A cgroup v2 `memory.max`.
    CgroupV2,
    /// A cgroup v1 `memory.limit_in_bytes`.
    CgroupV1,
    /// `RLIMIT_AS` (`Max address space` of `/proc/self/limits`).
    AddressSpace,
}

impl fmt::Display for LimitSource {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::MemTotal => "MemTotal (/proc/meminfo)",
            Self::CgroupV2 => "cgroup v2 memory.max",
            Self::CgroupV1 => "cgroup v1 memory.limit_in_bytes",
            Self::AddressSpace => "RLIMIT_AS (/proc/self/limits)",
        })
    }
}

/// The memory limits the process runs under, each `None` where there is
/// none or it cannot be read.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct SystemMemory {
    /// The machine's memory (`MemTotal`), bytes.
    pub mem_total: Option<u64>,
    /// The smallest memory limit of the process's cgroup and its
    /// ancestors, bytes, and which cgroup version set it.
    pub cgroup: Option<(u64, LimitSource)>,
    /// The soft `RLIMIT_AS`, bytes of address space.
    pub address_space: Option<u64>,
}

impl SystemMemory {
    /// Reads `/proc/meminfo`, `/proc/self/cgroup` with the cgroup files under
    /// `/sys/fs/cgroup`, and `/proc/self/limits`.
    pub fn read() -> Self {
        Self::read_with(|path| std::fs::read_to_string(path).ok())
    }

    /// As [`Self::read`], with `read_file` giving a file's text (`None`
    /// where it is absent): the tests pass fixtures.
    pub fn read_with(read_file: impl Fn(&str) -> Option<String>) -> Self {
        let cgroups = read_file("/proc/self/cgroup").unwrap_or_default();
        let paths = parse_cgroup_paths(&cgroups);
        // A cgroup is bound by its ancestors' limits too: walk up to the
        // root (the process's path may not exist in a container's view).
        let smallest = |root: &str, path: &str, file: &str, parse: fn(&str) -> Option<u64>| {
            let mut dir = path.trim_end_matches('/').to_string();
            let mut best: Option<u64> = None;
            loop {
                if let Some(v) = read_file(&format!("{root}{dir}/{file}")).and_then(|t| parse(&t)) {
                    best = Some(best.map_or(v, |b| b.min(v)));
                }
                match dir.rfind('/') {
                    Some(i) => dir.truncate(i),
                    None => break,
                }
            }
            best
        };
        let v2 = paths.v2.as_deref().and_then(|p| {
            smallest("/sys/fs/cgroup", p, "memory.max", parse_cgroup_v2_max)
                .map(|b| (b, LimitSource::CgroupV2))
        });
        let v1 = paths.v1_memory.as_deref().and_then(|p| {
            smallest(
                "/sys/fs/cgroup/memory",
                p,
                "memory.limit_in_bytes",
                parse_cgroup_v1_limit,
            )
            .map(|b| (b, LimitSource::CgroupV1))
        });
        let cgroup = match (v2, v1) {
            (Some(a), Some(b)) => Some(if a.0 <= b.0 { a } else { b }),
            (a, b) => a.or(b),
        };
        Self {
            mem_total: read_file("/proc/meminfo").and_then(|t| mem_total_bytes(&t)),
            cgroup,
            address_space: read_file("/proc/self/limits").and_then(|t| parse_address_space(&t)),
        }
    }

    /// The process's memory limit: the smallest reading, and which it was;
    /// `None` when nothing could be read.
    pub fn limit(&self) -> Option<(u64, LimitSource)> {
        [
            self.mem_total.map(|b| (b, LimitSource::MemTotal)),
            self.cgroup,
            self.address_space.map(|b| (b, LimitSource::AddressSpace)),
        ]
        .into_iter()
        .flatten()
        .min_by_key(|&(b, _)| b)
    }

    /// The default budget: [`DEFAULT_SHARE`] of [`Self::limit`], at most
    /// 256 GiB; 4 GiB when no limit could be read.
    pub fn default_budget(&self) -> u64 {
        self.limit().map_or(FALLBACK_BYTES, |(b, _)| {
            ((b as f64 * DEFAULT_SHARE) as u64).clamp(1, DEFAULT_CAP_BYTES)
        })
    }
}

/// `MemTotal` of a `/proc/meminfo` text, in bytes.
fn mem_total_bytes(meminfo: &str) -> Option<u64> {
    let line = meminfo.lines().find(|l| l.starts_with("MemTotal:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    kib.checked_mul(1024)
}

/// The cgroup paths of a `/proc/self/cgroup` text.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
struct CgroupPaths {
    /// The unified (v2) hierarchy's path: the `0::PATH` line.
    v2: Option<String>,
    /// The v1 memory controller's path: the `N:...memory...:PATH` line.
    v1_memory: Option<String>,
}

/// Reads the lines `ID:CONTROLLERS:PATH` of `/proc/self/cgroup`.
fn parse_cgroup_paths(text: &str) -> CgroupPaths {
    let mut paths = CgroupPaths::default();
    for line in text.lines() {
        let mut parts = line.splitn(3, ':');
        let (Some(id), Some(controllers), Some(path)) = (parts.next(), parts.next(), parts.next())
        else {
            continue;
        };
        if !path.starts_with('/') {
            continue;
        }
        if id == "0" && controllers.is_empty() {
            paths.v2 = Some(path.to_string());
        } else if controllers.split(',').any(|c| c == "memory") {
            paths.v1_memory = Some(path.to_string());
        }
    }
    paths
}

/// A cgroup v2 `memory.max`: bytes, or `None` for `max` (no limit).
fn parse_cgroup_v2_max(text: &str) -> Option<u64> {
    text.trim().parse().ok()
}

/// A cgroup v1 `memory.limit_in_bytes`: bytes, or `None` for the huge
/// value that means no limit.
fn parse_cgroup_v1_limit(text: &str) -> Option<u64> {
    text.trim()
        .parse()
        .ok()
        .filter(|&b| b < CGROUP_V1_UNLIMITED)
}

/// The soft limit of `Max address space` in a `/proc/self/limits` text,
/// bytes (`None` for `unlimited`).
fn parse_address_space(limits: &str) -> Option<u64> {
    let line = limits
        .lines()
        .find(|l| l.starts_with("Max address space"))?;
    line["Max address space".len()..]
        .split_whitespace()
        .next()?
        .parse()
        .ok()
}

/// What a job will allocate, by consumer, in bytes (saturating sums).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Estimate {
    /// (consumer, bytes), in the order added.
    pub items: Vec<(String, u64)>,
}

impl Estimate {
    /// Adds `bytes` for `what` (skipped when 0).
    pub fn add(&mut self, what: impl Into<String>, bytes: u64) {
        if bytes > 0 {
            self.items.push((what.into(), bytes));
        }
    }

    /// The sum of all items.
    pub fn total(&self) -> u64 {
        self.items
            .iter()
            .fold(0u64, |s, (_, b)| s.saturating_add(*b))
    }

    /// `Ok` when the total fits `budget`; otherwise a message with the
    /// total, the three largest consumers and the limit.
    pub fn check(&self, budget: MemoryBudget) -> Result<(), String> {
        let total = self.total();
        if total <= budget.limit.0 {
            return Ok(());
        }
        let mut items = self.items.clone();
        items.sort_by_key(|item| std::cmp::Reverse(item.1));
        let largest: Vec<String> = items
            .iter()
            .take(3)
            .map(|(w, b)| format!("{w} {}", ByteSize(*b)))
            .collect();
        Err(format!(
            "the render needs about {} (largest: {}) but the memory limit is {} (set with --memory-limit or render.memory_limit)",
            ByteSize(total),
            largest.join(", "),
            budget.limit
        ))
    }
}

/// Bytes of an authoring mesh vertex: position, normal, tangent, uv, colour.
pub const MESH_VERTEX_BYTES: u64 = 12 + 12 + 16 + 8 + 12;
/// Bytes of an authoring mesh triangle: three indices and a face material.
pub const MESH_TRIANGLE_BYTES: u64 = 12 + 4;
/// Bytes a technique's prepared vertex takes: its six attribute arrays.
pub const PREPARED_VERTEX_BYTES: u64 = 72;
/// Bytes a technique's prepared triangle takes at the peak, with its
/// indices, material and object, the crease pass's tables and the BVH:
/// fitted to a gouraud render of 500 tessellated spheres (1.98M triangles,
/// 1.07M vertices), whose peak resident size was 376 MB.
pub const PREPARED_TRIANGLE_BYTES: u64 = 150;

/// `a * b` in bytes, saturating (sizes here are only compared with a limit).
pub fn bytes_of(count: u64, each: u64) -> u64 {
    count.saturating_mul(each)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_parse_and_print() {
        for (s, v) in [
            ("123", 123),
            ("64K", 64 << 10),
            ("512M", 512 << 20),
            ("8G", 8 << 30),
            ("1.5GiB", 3 << 29),
            ("2 gb", 2 << 30),
            ("1t", 1 << 40),
        ] {
            assert_eq!(s.parse::<ByteSize>(), Ok(ByteSize(v)), "{s}");
        }
        for bad in ["", "G", "-1G", "0", "8X", "1e30T", "nan", "2000000T"] {
            assert!(bad.parse::<ByteSize>().is_err(), "{bad}");
        }
        assert_eq!(ByteSize(3 << 29).to_string(), "1.5 GiB");
        assert_eq!(ByteSize(100).to_string(), "100 B");
    }

    #[test]
    fn meminfo_is_read_and_the_default_is_positive() {
        let text = "MemTotal:       16318284 kB\nMemFree:         1000 kB\n";
        assert_eq!(mem_total_bytes(text), Some(16318284 * 1024));
        assert_eq!(mem_total_bytes("nothing"), None);
        assert!(MemoryBudget::machine_default().limit.0 > 0);
    }

    /// A reader of fixture files: `files` as (path, text); others absent.
    fn fixtures(files: &[(&str, &str)]) -> impl Fn(&str) -> Option<String> {
        let files: Vec<(String, String)> = files
            .iter()
            .map(|(p, t)| (p.to_string(), t.to_string()))
            .collect();
        move |path| {
            files
                .iter()
                .find(|(p, _)| p == path)
                .map(|(_, t)| t.clone())
        }
    }

    const MEMINFO_16G: (&str, &str) = ("/proc/meminfo", "MemTotal:       16777216 kB\n");
    const LIMITS_UNLIMITED: (&str, &str) = (
        "/proc/self/limits",
        "Max stack size            8388608              unlimited            bytes     \n\
         Max address space         unlimited            unlimited            bytes     \n",
    );

    #[test]
    fn without_limits_the_machine_memory_sets_the_budget() {
        let m = SystemMemory::read_with(fixtures(&[MEMINFO_16G, LIMITS_UNLIMITED]));
        assert_eq!(m.limit(), Some((16 << 30, LimitSource::MemTotal)));
        assert_eq!(m.default_budget(), 8 << 30);
        // Nothing readable: the fallback.
        assert_eq!(SystemMemory::read_with(fixtures(&[])).limit(), None);
        assert_eq!(
            SystemMemory::read_with(fixtures(&[])).default_budget(),
            FALLBACK_BYTES
        );
    }

    #[test]
    fn a_cgroup_v2_limit_of_the_process_or_an_ancestor_binds() {
        let cgroup = ("/proc/self/cgroup", "0::/user.slice/job.scope\n");
        let m = SystemMemory::read_with(fixtures(&[
            MEMINFO_16G,
            cgroup,
            ("/sys/fs/cgroup/user.slice/job.scope/memory.max", "max\n"),
            ("/sys/fs/cgroup/user.slice/memory.max", "2147483648\n"),
        ]));
        assert_eq!(m.limit(), Some((2 << 30, LimitSource::CgroupV2)));
        assert_eq!(m.default_budget(), 1 << 30);
        // "max" everywhere, or the files absent: no cgroup limit.
        let m = SystemMemory::read_with(fixtures(&[
            MEMINFO_16G,
            cgroup,
            ("/sys/fs/cgroup/user.slice/job.scope/memory.max", "max\n"),
        ]));
        assert_eq!(m.cgroup, None);
        assert_eq!(m.limit(), Some((16 << 30, LimitSource::MemTotal)));
        assert_eq!(parse_cgroup_v2_max("max\n"), None);
        assert_eq!(parse_cgroup_v2_max("1073741824\n"), Some(1 << 30));
    }

    #[test]
    fn a_cgroup_v1_limit_binds_and_its_huge_default_means_none() {
        let cgroup = (
            "/proc/self/cgroup",
            "12:pids:/docker/abc\n4:memory:/docker/abc\n1:name=systemd:/docker/abc\n0::/\n",
        );
        let limit = "/sys/fs/cgroup/memory/docker/abc/memory.limit_in_bytes";
        let m = SystemMemory::read_with(fixtures(&[MEMINFO_16G, cgroup, (limit, "536870912\n")]));
        assert_eq!(m.limit(), Some((512 << 20, LimitSource::CgroupV1)));
        let m = SystemMemory::read_with(fixtures(&[
            MEMINFO_16G,
            cgroup,
            (limit, "9223372036854771712\n"),
        ]));
        assert_eq!(m.cgroup, None);
        // A path the container cannot see: its root's file is read.
        let m = SystemMemory::read_with(fixtures(&[
            MEMINFO_16G,
            cgroup,
            (
                "/sys/fs/cgroup/memory/memory.limit_in_bytes",
                "1073741824\n",
            ),
        ]));
        assert_eq!(m.cgroup, Some((1 << 30, LimitSource::CgroupV1)));
        assert_eq!(
            parse_cgroup_paths("4:cpu,memory:/a\n0::/b\nbad line\n"),
            CgroupPaths {
                v2: Some("/b".into()),
                v1_memory: Some("/a".into())
            }
        );
    }

    #[test]
    fn rlimit_as_is_read_from_proc_limits() {
        let limits = (
            "/proc/self/limits",
            "Limit                     Soft Limit           Hard Limit           Units     \n\
             Max address space         4000000000           unlimited            bytes     \n",
        );
        let m = SystemMemory::read_with(fixtures(&[MEMINFO_16G, limits]));
        assert_eq!(m.address_space, Some(4_000_000_000));
        assert_eq!(m.limit(), Some((4_000_000_000, LimitSource::AddressSpace)));
        assert_eq!(m.default_budget(), 2_000_000_000);
        assert_eq!(parse_address_space(LIMITS_UNLIMITED.1), None);
        assert_eq!(parse_address_space(""), None);
    }

    #[test]
    fn shadow_maps_get_a_quarter_of_the_budget_up_to_the_cap() {
        assert_eq!(MemoryBudget::new(64 << 20).shadow_map_bytes(), 16 << 20);
        assert_eq!(MemoryBudget::new(2 << 30).shadow_map_bytes(), 512 << 20);
        assert_eq!(MemoryBudget::new(64 << 30).shadow_map_bytes(), 512 << 20);
        assert_eq!(MemoryBudget::new(3).shadow_map_bytes(), 0);
    }

    #[test]
    fn estimate_names_the_largest_consumers() {
        let mut e = Estimate::default();
        e.add("film", 100 << 20);
        e.add("triangles", 3 << 30);
        e.add("textures", 1 << 30);
        e.add("bvh", 10 << 20);
        assert!(e.check(MemoryBudget::new(8 << 30)).is_ok());
        let msg = e.check(MemoryBudget::new(1 << 30)).expect_err("over");
        assert!(
            msg.contains("triangles 3.0 GiB, textures 1.0 GiB, film 100.0 MiB")
                && msg.contains("limit is 1.0 GiB")
                && !msg.contains("bvh"),
            "{msg}"
        );
    }
}
