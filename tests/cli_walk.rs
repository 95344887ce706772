//! A random walk over the command line (issue 61): every subcommand with random flags and values, hostile
//! ones among them (absurd sizes, NaN and huge numbers, frame fields of 70,000 digits, FIFOs, folders that take
//! no file, B44), each run under a memory limit and a timeout. Every run must end with exit code 0 or 2, never
//! say "internal error" or "panicked", never time out, and every EXR it writes must hold finite values only.
//! The walk is reproducible: `FLARELAB_WALK_SEED` picks it (default: a fixed seed, so CI's runs are the same
//! each time; the seed is printed), `FLARELAB_WALK_RUNS` how many commands (default 160). It prints the number
//! of runs, how each ended, and the peak RSS of the worst accepted run.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// A small deterministic generator (xorshift64*): the walk needs no more.
struct Walk(u64);

impl Walk {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_f491_4f6c_dd1d)
    }
    fn pick<'a>(&mut self, items: &[&'a str]) -> &'a str {
        items[(self.next() % items.len() as u64) as usize]
    }
    fn chance(&mut self, percent: u64) -> bool {
        self.next() % 100 < percent
    }
    /// One of `good` four times in five, else one of `bad`.
    fn mix<'a>(&mut self, good: &[&'a str], bad: &[&'a str]) -> &'a str {
        if self.chance(80) { self.pick(good) } else { self.pick(bad) }
    }
}

/// How a run ended.
struct Ended {
    code: Option<i32>,
    stderr: String,
    peak_rss_kb: i64,
    timed_out: bool,
}

/// The largest virtual address space a run may take (a runaway allocation fails there instead of taking the
/// machine; lavapipe maps several GiB of address space it never touches).
const ADDRESS_SPACE_BYTES: u64 = 24 << 30;

/// Runs `flarelab args` in `dir` with the limits above; its peak RSS from the kernel's own account (wait4).
fn run(args: &[String], dir: &Path, timeout: Duration) -> Ended {
    use std::os::unix::process::CommandExt;
    let stderr_path = dir.join(format!("stderr-{}.txt", std::process::id()));
    let stderr = std::fs::File::create(&stderr_path).unwrap();
    let mut command = Command::new(env!("CARGO_BIN_EXE_flarelab"));
    command
        .args(args)
        .current_dir(dir)
        .env_remove("DISPLAY")
        .env_remove("WAYLAND_DISPLAY")
        .env("FLARELAB_CACHE_DIR", dir.join("cache"))
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(stderr);
    // SAFETY: only async-signal-safe calls (setrlimit) between fork and exec.
    unsafe {
        command.pre_exec(|| {
            let limit = libc::rlimit { rlim_cur: ADDRESS_SPACE_BYTES, rlim_max: ADDRESS_SPACE_BYTES };
            libc::setrlimit(libc::RLIMIT_AS, &limit);
            Ok(())
        });
    }
    let child = command.spawn().expect("flarelab starts");
    let pid = child.id() as libc::pid_t;
    let started = Instant::now();
    let mut status = 0;
    // SAFETY: a zeroed rusage is a valid value for wait4 to fill.
    let mut usage: libc::rusage = unsafe { std::mem::zeroed() };
    let mut timed_out = false;
    loop {
        // SAFETY: `pid` is our child; `status` and `usage` are valid for writing.
        let done = unsafe { libc::wait4(pid, &mut status, libc::WNOHANG, &mut usage) };
        if done == pid {
            break;
        }
        if started.elapsed() > timeout && !timed_out {
            timed_out = true;
            // SAFETY: signalling our own child.
            unsafe { libc::kill(pid, libc::SIGKILL) };
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    std::mem::forget(child);
    let code = libc::WIFEXITED(status).then(|| libc::WEXITSTATUS(status));
    let stderr = std::fs::read_to_string(&stderr_path).unwrap_or_default();
    Ended { code, stderr, peak_rss_kb: usage.ru_maxrss, timed_out }
}

/// Every value of every channel of every part of the EXR `path` is finite.
fn exr_is_finite(path: &Path) -> Result<(), String> {
    let image = exr::prelude::read_all_flat_layers_from_file(path).map_err(|e| e.to_string())?;
    for layer in &image.layer_data {
        for channel in &layer.channel_data.list {
            let finite = match &channel.sample_data {
                exr::prelude::FlatSamples::F16(v) => v.iter().all(|x| x.to_f32().is_finite()),
                exr::prelude::FlatSamples::F32(v) => v.iter().all(|x| x.is_finite()),
                exr::prelude::FlatSamples::U32(_) => true,
            };
            if !finite {
                return Err(format!("channel {} holds a value that is not finite", channel.name));
            }
        }
    }
    Ok(())
}

/// One random command in `dir` (see the module documentation).
fn command(walk: &mut Walk, dir: &Path, fifo: &Path) -> Vec<String> {
    let fifo = fifo.display().to_string();
    let lens = walk.mix(&["heliar", "tessar", "dgauss", "panavision_anamorphic_us20060050403"], &["nope", "", "FIFO"]);
    let lens = if lens == "FIFO" { fifo.as_str() } else { lens };
    let out_png = walk.mix(&["o.png", "o.exr"], &["/sys/o.png", "no/such/o.png", "o.%070000d.png", "o.txt"]);
    let mut args: Vec<String> = Vec::new();
    let mut push = |items: &[&str]| args.extend(items.iter().map(|s| s.to_string()));
    match walk.next() % 9 {
        0..=3 => {
            push(&["render"]);
            if walk.chance(60) {
                push(&[lens]);
            }
            push(&["-o", out_png, "--device", walk.pick(&["cpu", "cpu", "auto"])]);
            let size = walk.mix(&["64x36", "96x64", "160x90"], &["0x0", "8192x8192", "100000x1", "abc", "-1x5"]);
            push(&["--size", size]);
            let flags: [(&str, &[&str]); 16] = [
                ("--exposure-ev", &["auto", "7", "-1e308", "nan", "1e9", "40", "inf"]),
                ("--light-deg", &["10,5", "89,89", "nan,0", "1e300,0", "-45,30", "x"]),
                ("--f-number", &["2", "0", "-1", "1e300", "nan", "16"]),
                ("--exr-compression", &["zip", "piz", "b44", "b44a", "dwaa", "pxr24", "none", "lzma"]),
                ("--exr-type", &["auto", "half", "float", "int"]),
                ("--desqueeze", &["1", "2", "4", "0", "-3", "auto", "1e9", "nan"]),
                ("--shutter-deg", &["0", "180", "360", "1e9", "-5", "nan"]),
                ("--frames", &["1-2", "1-1000000000000", "5-1", "-2--1", "9223372036854775806-9223372036854775807"]),
                ("--look", &["", "nope", "x,x,x,x"]),
                ("--method", &["paraxial", "blended", "raygrid", "ray", "photo", "nope"]),
                ("--grid", &["8", "0", "100000", "-1"]),
                ("--spectrum", &["rgb", "3", "0", "1000000", "nope"]),
                ("--starburst-ev", &["0", "1e308", "nan", "-40"]),
                ("--accumulation-divisor", &["1", "2", "3", "4", "0"]),
                ("--sensor-mm", &["36", "0", "-1", "1e308", "nan"]),
                ("--layers", &["ghosts", "none", "all"]),
            ];
            for (flag, values) in flags {
                if walk.chance(12) {
                    push(&[flag, walk.pick(values)]);
                }
            }
            if walk.chance(10) {
                push(&["--cube", fifo.as_str()]);
            }
            if walk.chance(10) {
                push(&["--preset", walk.pick(&["default", "anamorphic-panavision", "nope", fifo.as_str()])]);
            }
        }
        4 => {
            push(&["ghosts", lens, "--field-deg", walk.mix(&["10", "0", "25"], &["nan", "1e300", "89.9", "-5"])]);
            if walk.chance(40) {
                match walk.next() % 3 {
                    0 => push(&["--json"]),
                    1 => push(&["--report"]),
                    _ => push(&["--report", "--csv"]),
                }
            }
        }
        5 => {
            push(&["trace", lens, "--field-deg", walk.mix(&["5", "0"], &["nan", "95"])]);
            if walk.chance(50) {
                push(&["--pupil", walk.mix(&["0.5,0", "0,0.3"], &["nan,0", "1e300,1", "2,2"])]);
            }
            if walk.chance(40) {
                push(&["--ghost", walk.mix(&["2,5", "1,4"], &["0,0", "99,100", "x", "5,2"])]);
            }
            if walk.chance(30) {
                push(&["--json"]);
            }
        }
        6 => {
            let sub = walk.pick(&["info", "list", "convert"]);
            push(&["lens", sub]);
            if sub != "list" {
                push(&[lens]);
            }
            if sub == "convert" {
                push(&["--to", walk.mix(&["json", "zmx", "dat", "lens"], &["xml", "txt"])]);
                push(&["-o", walk.mix(&["l.out"], &["/sys/l.out", "no/such/l.out"])]);
            }
        }
        7 => {
            push(&["preset", "new", "-o", walk.mix(&["p.json"], &["/sys/p.json", "no/such/p.json"])]);
            if walk.chance(50) {
                push(&[lens]);
            }
        }
        _ => {
            let sub = walk.pick(&["synth-shot", "synth-dof"]);
            push(&[sub, "--size", walk.mix(&["64x36", "96x54", "1x1"], &["0x0", "8192x8192"])]);
            let out = if sub == "synth-shot" {
                walk.mix(&["s/f.####.exr"], &["s.%070000d.exr", "/sys/s.####.exr", "s/f.####.png"])
            } else {
                walk.mix(&["street.exr"], &["/sys/street.exr"])
            };
            push(&["-o", out]);
            if sub == "synth-dof" {
                push(&["--depth", walk.mix(&["street_z.exr"], &["/sys/z.exr", "z.png"])]);
            }
            if sub == "synth-shot" {
                push(&["--frames", walk.pick(&["1-2", "1-3", "0-0", "2-1"])]);
            }
        }
    }
    let _ = dir;
    args
}

#[test]
fn a_random_walk_over_the_command_line_ends_in_0_or_2_and_writes_finite_images() {
    let seed: u64 = std::env::var("FLARELAB_WALK_SEED").ok().and_then(|s| s.parse().ok()).unwrap_or(61);
    let runs: usize = std::env::var("FLARELAB_WALK_RUNS").ok().and_then(|s| s.parse().ok()).unwrap_or(160);
    let mut walk = Walk(seed.wrapping_mul(0x9e37_79b9_7f4a_7c15) | 1);
    let dir = tempfile::tempdir().unwrap();
    let fifo = dir.path().join("fifo.json");
    assert!(Command::new("mkfifo").arg(&fifo).status().unwrap().success());
    let (mut zero, mut two, mut worst) = (0usize, 0usize, (0i64, Vec::<String>::new()));
    let mut failures = Vec::new();
    for k in 0..runs {
        let work = dir.path().join(format!("run{k}"));
        std::fs::create_dir_all(&work).unwrap();
        let args = command(&mut walk, &work, &fifo);
        let ended = run(&args, &work, Duration::from_secs(120));
        let what = format!("run {k}: flarelab {}", args.join(" "));
        if ended.timed_out {
            failures.push(format!("{what}: timed out"));
            continue;
        }
        if ended.stderr.contains("internal error") || ended.stderr.contains("panicked") {
            failures.push(format!("{what}: {}", ended.stderr.trim()));
        }
        match ended.code {
            Some(0) => {
                zero += 1;
                if ended.peak_rss_kb > worst.0 {
                    worst = (ended.peak_rss_kb, args.clone());
                }
                for entry in walkdir(&work) {
                    if entry.extension().is_some_and(|e| e == "exr")
                        && let Err(e) = exr_is_finite(&entry)
                    {
                        failures.push(format!("{what}: {}: {e}", entry.display()));
                    }
                }
            }
            Some(2) => {
                two += 1;
                if std::env::var_os("FLARELAB_WALK_SAY").is_some() {
                    println!("{what}: {}", ended.stderr.trim());
                }
            }
            other => failures.push(format!("{what}: exit {other:?}: {}", ended.stderr.trim())),
        }
        let _ = std::fs::remove_dir_all(&work);
    }
    println!(
        "seed {seed}: {runs} runs, {zero} accepted (exit 0), {two} refused (exit 2), {} failed; the worst accepted \
         run peaked at {:.0} MB RSS: flarelab {}",
        failures.len(),
        worst.0 as f64 / 1024.0,
        worst.1.join(" ")
    );
    assert!(failures.is_empty(), "{}", failures.join("\n"));
    assert!(zero > runs / 10 && two > runs / 10, "the walk accepts and refuses: {zero} and {two}");
}

/// Every file under `dir`.
fn walkdir(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for entry in std::fs::read_dir(&d).into_iter().flatten().flatten() {
            let path = entry.path();
            if path.is_dir() {
                stack.push(path);
            } else {
                out.push(path);
            }
        }
    }
    out
}
