//! A server (`walkthrough renderer serve`, `walkthrough sma`, …) started as a child process with
//! `--listen 127.0.0.1:0`: the OS picks the port, the child reports it on its `listening on` line
//! (`conventions::listening`), and the child is killed when its handle is dropped.

use std::fs::File;
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::time::Duration;

use anyhow::Context;

/// How long a child may take to bind its port (scene load, BVH build, wgpu start on Mesa).
pub const START_TIMEOUT: Duration = Duration::from_secs(120);

/// `/proc`'s clock ticks (USER_HZ: 100 on every Linux architecture, fixed by its ABI).
const CLOCK_TICKS_PER_SECOND: f64 = 100.0;

/// A running child process; killed when dropped, on every exit path (a failure, a panic in a test).
pub struct Process {
    name: String,
    child: Child,
    log: Option<PathBuf>,
}

impl Process {
    /// Starts `exe args`, its output appended to `log` when given (else stderr is inherited and
    /// stdout dropped).
    pub fn spawn(
        exe: &Path,
        name: &str,
        args: &[String],
        log: Option<&Path>,
    ) -> anyhow::Result<Process> {
        let stdout = match log {
            Some(log) => Stdio::from(log_file(log)?),
            None => Stdio::null(),
        };
        Process::spawn_with_stdout(exe, name, args, log, stdout)
    }

    fn spawn_with_stdout(
        exe: &Path,
        name: &str,
        args: &[String],
        log: Option<&Path>,
        stdout: Stdio,
    ) -> anyhow::Result<Process> {
        let mut command = Command::new(exe);
        command
            .args(args)
            .stdin(Stdio::null())
            .stdout(stdout)
            .env("NODEVICE_SELECT", "1");
        if let Some(log) = log {
            command.stderr(log_file(log)?);
        }
        let child = command
            .spawn()
            .with_context(|| format!("starting {} {}", exe.display(), args.join(" ")))?;
        Ok(Process {
            name: name.to_string(),
            child,
            log: log.map(Path::to_path_buf),
        })
    }

    /// Waits for the child's `listening on` line; its stdout keeps going to the log.
    pub fn listening_addr(&mut self, timeout: Duration) -> anyhow::Result<SocketAddr> {
        let stdout = self.child.stdout.take().context("stdout already taken")?;
        let found = match &self.log {
            Some(log) => conventions::listening::read_addr(stdout, log_file(log)?, timeout),
            None => conventions::listening::read_addr(stdout, std::io::sink(), timeout),
        };
        found.map_err(|e| self.failure(&format!("did not listen: {e}")))
    }

    /// Kills the child now (a renderer dying mid-run) and reaps it.
    pub fn kill(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }

    /// CPU seconds (user + system) the child has used so far, read from `/proc` (Linux); `None`
    /// elsewhere or once the child is reaped.
    pub fn cpu_seconds(&self) -> Option<f64> {
        let stat = std::fs::read_to_string(format!("/proc/{}/stat", self.child.id())).ok()?;
        // After the command name (in parentheses, and it may hold spaces) come the fields from
        // the 3rd on; utime and stime are the 14th and 15th, in clock ticks.
        let fields: Vec<&str> = stat.rsplit_once(')')?.1.split_whitespace().collect();
        let ticks = |i: usize| fields.get(i - 3)?.parse::<f64>().ok();
        Some((ticks(14)? + ticks(15)?) / CLOCK_TICKS_PER_SECOND)
    }

    /// Stops the child as Ctrl-C does (SIGINT: a server's clean stop) and waits for it to exit,
    /// within `timeout`; past it, kills it and fails.
    pub fn interrupt_and_wait(&mut self, timeout: Duration) -> anyhow::Result<ExitStatus> {
        self.signal(libc::SIGINT);
        let deadline = std::time::Instant::now() + timeout;
        loop {
            if let Some(status) = self.exited() {
                return Ok(status);
            }
            if std::time::Instant::now() > deadline {
                let failure = self.failure(&format!("did not stop within {timeout:?} of SIGINT"));
                self.kill();
                return Err(failure);
            }
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    /// Stops the child with SIGSTOP (a hung host: its sockets stay open, it answers nothing).
    pub fn pause(&self) {
        self.signal(libc::SIGSTOP);
    }

    /// Lets a paused child go on (SIGCONT).
    pub fn resume(&self) {
        self.signal(libc::SIGCONT);
    }

    fn signal(&self, signal: libc::c_int) {
        // SAFETY: kill(2) with a child's pid and a signal number has no memory effects here.
        unsafe {
            libc::kill(self.child.id() as libc::pid_t, signal);
        }
    }

    /// Caps the size of any file the child writes from now on at `bytes` (RLIMIT_FSIZE): a
    /// write past it fails (EFBIG) as on a full disk, once the child ignores SIGXFSZ, whose
    /// default action would end it. Linux only; an error elsewhere.
    pub fn cap_file_size(&self, bytes: u64) -> anyhow::Result<()> {
        let limit = libc::rlimit {
            rlim_cur: bytes,
            rlim_max: libc::RLIM_INFINITY,
        };
        // SAFETY: prlimit(2) on a child's pid, with a valid new limit and no old one asked for.
        let done = unsafe {
            libc::prlimit(
                self.child.id() as libc::pid_t,
                libc::RLIMIT_FSIZE,
                &limit,
                std::ptr::null_mut(),
            )
        };
        anyhow::ensure!(
            done == 0,
            "capping {}'s file size: {}",
            self.name,
            std::io::Error::last_os_error()
        );
        Ok(())
    }

    /// Keeps every thread of the child, and those it starts later, on CPU `cpu` alone: a host of
    /// its own for the farm benchmark on one machine. Linux only; an error elsewhere.
    pub fn pin_to_cpu(&self, cpu: usize) -> anyhow::Result<()> {
        let tasks = std::fs::read_dir(format!("/proc/{}/task", self.child.id()))
            .with_context(|| format!("listing {}'s threads", self.name))?;
        for task in tasks {
            let tid: libc::pid_t = task?.file_name().to_string_lossy().parse()?;
            pin_thread(tid, cpu)?;
        }
        Ok(())
    }

    /// The child's resident memory (`VmRSS`), bytes, while it runs on Linux.
    pub fn resident_bytes(&self) -> Option<u64> {
        let status = std::fs::read_to_string(format!("/proc/{}/status", self.child.id())).ok()?;
        let line = status.lines().find(|l| l.starts_with("VmRSS:"))?;
        let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
        Some(kib * 1024)
    }

    /// The address of the child's `"{who} listening on ADDR"` line, once its log has it.
    pub fn announced(&self, who: &str, timeout: Duration) -> anyhow::Result<SocketAddr> {
        let deadline = std::time::Instant::now() + timeout;
        let prefix = format!("{who} listening on ");
        loop {
            let text = self.log_text();
            let line = text.lines().find(|l| l.starts_with(&prefix));
            if let Some(addr) = line.and_then(conventions::listening::parse) {
                return Ok(addr);
            }
            if std::time::Instant::now() > deadline {
                return Err(self.failure(&format!("printed no `{prefix}` line")));
            }
            std::thread::sleep(Duration::from_millis(50));
        }
    }

    /// The exit status once the child has ended.
    pub fn exited(&mut self) -> Option<ExitStatus> {
        self.child.try_wait().ok().flatten()
    }

    /// An error naming the process and the end of its log.
    pub fn failure(&self, what: &str) -> anyhow::Error {
        let Some(log) = &self.log else {
            return anyhow::anyhow!("{} {what}", self.name);
        };
        let text = std::fs::read_to_string(log).unwrap_or_default();
        let lines: Vec<&str> = text.lines().collect();
        let tail = &lines[lines.len().saturating_sub(15)..];
        anyhow::anyhow!(
            "{} {what} (log {}):\n{}",
            self.name,
            log.display(),
            tail.join("\n")
        )
    }

    /// The log's text so far (empty without a log).
    pub fn log_text(&self) -> String {
        self.log
            .as_ref()
            .and_then(|log| std::fs::read_to_string(log).ok())
            .unwrap_or_default()
    }
}

impl Drop for Process {
    fn drop(&mut self) {
        self.kill();
    }
}

fn log_file(path: &Path) -> anyhow::Result<File> {
    File::options()
        .create(true)
        .append(true)
        .open(path)
        .with_context(|| format!("opening {}", path.display()))
}

/// Keeps thread `tid` (0: the caller) on CPU `cpu`; threads it starts later inherit the mask.
pub fn pin_thread(tid: libc::pid_t, cpu: usize) -> anyhow::Result<()> {
    // SAFETY: a zeroed cpu_set_t is the empty set; CPU_SET writes within it for cpu <
    // CPU_SETSIZE (checked); sched_setaffinity reads `size_of` bytes of it.
    let status = unsafe {
        anyhow::ensure!(cpu < libc::CPU_SETSIZE as usize, "no CPU {cpu}");
        let mut set: libc::cpu_set_t = std::mem::zeroed();
        libc::CPU_SET(cpu, &mut set);
        libc::sched_setaffinity(tid, std::mem::size_of::<libc::cpu_set_t>(), &set)
    };
    anyhow::ensure!(
        status == 0,
        "pinning thread {tid} to CPU {cpu}: {}",
        std::io::Error::last_os_error()
    );
    Ok(())
}

/// A child server and the address it reported.
pub struct Server {
    pub process: Process,
    pub addr: SocketAddr,
}

/// Starts `exe args` (whose args include `--listen 127.0.0.1:0`) and waits for its address.
pub fn start_server(
    exe: &Path,
    name: &str,
    args: &[String],
    log: Option<&Path>,
) -> anyhow::Result<Server> {
    let mut process = Process::spawn_with_stdout(exe, name, args, log, Stdio::piped())?;
    let addr = process.listening_addr(START_TIMEOUT)?;
    Ok(Server { process, addr })
}

/// `walkthrough renderer serve` on `scene`, with `threads` workers (all cores when `None`).
pub fn start_renderer(
    exe: &Path,
    scene: &str,
    threads: Option<usize>,
    log: Option<&Path>,
) -> anyhow::Result<Server> {
    start_renderer_with(exe, scene, threads, &[], log)
}

/// [`start_renderer`] with more `walkthrough renderer serve` flags (e.g. `--join SMA`).
pub fn start_renderer_with(
    exe: &Path,
    scene: &str,
    threads: Option<usize>,
    flags: &[String],
    log: Option<&Path>,
) -> anyhow::Result<Server> {
    let mut args = strings(&[
        "renderer",
        "serve",
        "--scene",
        scene,
        "--listen",
        "127.0.0.1:0",
    ]);
    if let Some(threads) = threads {
        args.extend(["--threads".to_string(), threads.to_string()]);
    }
    args.extend(flags.iter().cloned());
    start_server(exe, "renderer", &args, log)
}

/// `walkthrough sma` on `scene` with the renderers at `renderers` and more `flags`.
pub fn start_sma(
    exe: &Path,
    scene: &str,
    renderers: &[SocketAddr],
    flags: &[String],
    log: Option<&Path>,
) -> anyhow::Result<Server> {
    let mut args = strings(&["sma", "--scene", scene, "--listen", "127.0.0.1:0"]);
    args.extend(flags.iter().cloned());
    for renderer in renderers {
        args.extend(["--renderer".to_string(), renderer.to_string()]);
    }
    start_server(exe, "sma", &args, log)
}

/// `["a", "b"]` as owned strings, for argument lists.
pub fn strings(v: &[&str]) -> Vec<String> {
    v.iter().map(|s| s.to_string()).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn shell(name: &str, script: &str) -> Process {
        Process::spawn(Path::new("/bin/sh"), name, &strings(&["-c", script]), None).unwrap()
    }

    #[test]
    fn an_interrupt_stops_a_child_and_one_that_ignores_it_is_killed_at_the_timeout() {
        let mut plain = shell("sleeper", "exec sleep 30");
        let status = plain.interrupt_and_wait(Duration::from_secs(20)).unwrap();
        assert!(!status.success(), "sleep ends by the signal: {status}");
        // It says when its trap is set: a signal before that would end it.
        let ready = std::env::temp_dir().join(format!("testkit-stubborn-{}", std::process::id()));
        let _ = std::fs::remove_file(&ready);
        let script = format!("trap '' INT; touch '{}'; exec sleep 30", ready.display());
        let mut stubborn = shell("stubborn", &script);
        let deadline = std::time::Instant::now() + Duration::from_secs(20);
        while !ready.exists() {
            assert!(
                std::time::Instant::now() < deadline,
                "the shell never set its trap"
            );
            std::thread::sleep(Duration::from_millis(10));
        }
        let _ = std::fs::remove_file(&ready);
        let started = std::time::Instant::now();
        assert!(
            stubborn
                .interrupt_and_wait(Duration::from_millis(300))
                .is_err()
        );
        assert!(started.elapsed() < Duration::from_secs(20));
        assert!(stubborn.exited().is_some(), "killed and reaped");
    }
}
