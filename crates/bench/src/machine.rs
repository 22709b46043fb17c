//! What machine a benchmark ran on, stated beside every figure.

pub fn describe() -> String {
    let cpu = std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("model name"))
                .map(|l| l.split(':').nth(1).unwrap_or("").trim().to_string())
        })
        .unwrap_or_else(|| "unknown CPU".into());
    let cores = std::thread::available_parallelism()
        .map(|n| n.get())
        .unwrap_or(0);
    let mem_gib = std::fs::read_to_string("/proc/meminfo")
        .ok()
        .and_then(|s| {
            s.lines()
                .next()
                .and_then(|l| l.split_whitespace().nth(1))
                .and_then(|kb| kb.parse::<f64>().ok())
        })
        .map(|kb| kb / 1024.0 / 1024.0)
        .unwrap_or(0.0);
    format!("{cpu}, {cores} cores, {mem_gib:.0} GiB, no GPU unless stated (wgpu on Mesa)")
}

/// The one-minute load average now, as `/proc/loadavg` gives it: how busy other processes kept
/// the machine while a figure was measured.
pub fn load_average() -> String {
    std::fs::read_to_string("/proc/loadavg")
        .ok()
        .and_then(|load| load.split_whitespace().next().map(str::to_string))
        .unwrap_or_else(|| "unknown".into())
}

/// When and on what code a figure is measured: today's UTC date and the checkout's commit (`+`
/// when its code has uncommitted changes; the reports a benchmark writes do not count), so a
/// report that keeps older views' figures beside new ones says which is which.
pub fn measured_stamp() -> String {
    let output = |program: &str, args: &[&str]| {
        std::process::Command::new(program)
            .args(args)
            .output()
            .ok()
            .filter(|o| o.status.success())
            .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string())
    };
    let date = output("date", &["-u", "+%Y-%m-%d"]).unwrap_or_else(|| "unknown date".into());
    let commit = output("git", &["rev-parse", "--short", "HEAD"]).unwrap_or_else(|| "?".into());
    let code = ["Cargo.toml", "Cargo.lock", "crates", "src", "tests"];
    let dirty = output(
        "git",
        &[
            &["status", "--porcelain", "--untracked-files=no", "--"][..],
            &code[..],
        ]
        .concat(),
    )
    .is_some_and(|s| !s.is_empty());
    format!("{date} at {commit}{}", if dirty { "+" } else { "" })
}
