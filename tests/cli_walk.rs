//! A random walk over the command line (issue 61): every subcommand (render, ghosts, trace, lens, preset,
//! synth-shot, synth-dof, bake, classify, photo-lut, dof, bench) with random flags and values, hostile
//! ones among them (absurd sizes, NaN and huge numbers, frame fields of 70,000 digits, FIFOs, folders that take
//! no file, B44), each run under a memory limit and a timeout. Every run must end with exit code 0 or 2, never
//! say "internal error" or "panicked", never time out, and every EXR it writes must hold finite values only.
//! The walk is reproducible: `FLARELAB_WALK_SEED` picks it (default: a fixed seed, so CI's runs are the same
//! each time; the seed is printed), `FLARELAB_WALK_RUNS` how many commands (default 160), `FLARELAB_WALK_SAY`
//! prints every run (its command, exit code, seconds, peak RSS and last line of stderr). It prints the number
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
    seconds: f64,
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
    Ended { code, stderr, peak_rss_kb: usage.ru_maxrss, timed_out, seconds: started.elapsed().as_secs_f64() }
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

/// The files the walk's commands read, made once before it (absolute paths): good ones and hostile ones.
struct Inputs {
    /// A FIFO (an input that blocks a reader forever).
    fifo: String,
    /// A folder of three photos of a flare named by their angles (`flare_0deg.png` ...).
    photos: String,
    /// A folder with no image.
    empty: String,
    /// A plate and its depth map (`synth-dof`).
    street: String,
    street_z: String,
    /// A small baked LUT, and its first half.
    lut: String,
    torn_lut: String,
    /// The plate's first half.
    torn_exr: String,
}

impl Inputs {
    /// Makes the inputs in `dir` with the program itself; each must succeed.
    fn make(dir: &Path) -> Self {
        let at = |name: &str| dir.join(name).display().to_string();
        let fifo = dir.join("fifo.json");
        assert!(Command::new("mkfifo").arg(&fifo).status().unwrap().success());
        std::fs::create_dir_all(dir.join("photos")).unwrap();
        std::fs::create_dir_all(dir.join("empty")).unwrap();
        let mut made: Vec<Vec<String>> = [0, 4, 8]
            .iter()
            .map(|deg| {
                let light = format!("{deg},0");
                let out = at(&format!("photos/flare_{deg}deg.png"));
                ["render", "heliar", "--device", "cpu", "--size", "96x64", "--light-deg", &light, "-o", &out]
                    .map(String::from)
                    .to_vec()
            })
            .collect();
        made.push(
            ["synth-dof", "--size", "96x54", "-o", &at("street.exr"), "--depth", &at("street_z.exr")]
                .map(String::from)
                .to_vec(),
        );
        made.push(
            [
                "bake",
                "heliar",
                "-o",
                &at("l.flut"),
                "--device",
                "cpu",
                "--res",
                "16",
                "--grid",
                "8",
                "--theta-max",
                "5",
            ]
            .map(String::from)
            .to_vec(),
        );
        for args in &made {
            let ended = run(args, dir, Duration::from_secs(120));
            assert_eq!(ended.code, Some(0), "flarelab {}: {}", args.join(" "), ended.stderr);
        }
        for (whole, torn) in [("l.flut", "torn.flut"), ("street.exr", "torn.exr")] {
            let bytes = std::fs::read(dir.join(whole)).unwrap();
            std::fs::write(dir.join(torn), &bytes[..bytes.len() / 2]).unwrap();
        }
        Self {
            fifo: fifo.display().to_string(),
            photos: at("photos"),
            empty: at("empty"),
            street: at("street.exr"),
            street_z: at("street_z.exr"),
            lut: at("l.flut"),
            torn_lut: at("torn.flut"),
            torn_exr: at("torn.exr"),
        }
    }
}

/// One random command (see the module documentation), its outputs named relative to the folder it runs in.
fn command(walk: &mut Walk, inputs: &Inputs) -> Vec<String> {
    let fifo = inputs.fifo.clone();
    let lens = walk.mix(&["heliar", "tessar", "dgauss", "panavision_anamorphic_us20060050403"], &["nope", "", "FIFO"]);
    let lens = if lens == "FIFO" { fifo.as_str() } else { lens };
    let out_png = walk.mix(&["o.png", "o.exr"], &["/sys/o.png", "no/such/o.png", "o.%070000d.png", "o.txt"]);
    let mut args: Vec<String> = Vec::new();
    let mut push = |items: &[&str]| args.extend(items.iter().map(|s| s.to_string()));
    match walk.next() % 14 {
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
            if walk.chance(10) {
                push(&["--lut", walk.pick(&[&inputs.lut, &inputs.torn_lut, fifo.as_str(), "nope.flut"])]);
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
        8 => {
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
        9 => {
            // Small bakes (a few seconds), with hostile settings among them.
            // The anamorphic lens's 885 ghosts take minutes to bake: small lenses only, and hostile names.
            let lens = walk.mix(&["heliar", "tessar", "dgauss"], &["nope", &inputs.fifo]);
            push(&["bake", lens, "--device", walk.pick(&["cpu", "auto"])]);
            push(&["-o", walk.mix(&["l.flut"], &["/sys/l.flut", "no/such/l.flut", "l.%070000d.flut", "l.png"])]);
            push(&["--res", walk.mix(&["8", "16"], &["0", "100000", "nan", "-8"])]);
            push(&["--grid", walk.mix(&["4", "8"], &["0", "1000000", "-1"])]);
            push(&["--theta-max", walk.mix(&["2", "4"], &["nan", "1e300", "90", "-1", "0"])]);
            let optional: [(&str, &[&str]); 7] = [
                ("--diagonal-texels", &["0", "64", "100000", "-1"]),
                ("--min-step", &["1", "0", "nan", "1e-300", "1e300"]),
                ("--phi-steps", &["0", "1", "100", "-1"]),
                ("--tolerance", &["0.5", "0", "nan", "-1"]),
                ("--detail-tolerance", &["0.1", "nan", "-1"]),
                ("--f-number", &["4", "0", "nan", "1e300"]),
                ("--update", &[&inputs.lut, &inputs.torn_lut, fifo.as_str(), "nope.flut"]),
            ];
            for (flag, values) in optional {
                if walk.chance(20) {
                    push(&[flag, walk.pick(values)]);
                }
            }
        }
        10 => {
            let lens = walk.mix(&["heliar", "tessar", "dgauss"], &["nope", &inputs.fifo]);
            push(&["classify", lens, "--theta-max", walk.mix(&["5", "10"], &["nan", "1e300", "90", "-1"])]);
            let optional: [(&str, &[&str]); 4] = [
                ("--threshold", &["0.02", "0", "nan", "-1", "1e300"]),
                ("--faint", &["1e-4", "0", "nan", "-1"]),
                ("--force-nonlinear", &["2,5", "x", "99,100", "5,2", ""]),
                ("--f-number", &["4", "0", "nan"]),
            ];
            for (flag, values) in optional {
                if walk.chance(25) {
                    push(&[flag, walk.pick(values)]);
                }
            }
            if walk.chance(30) {
                push(&["--json"]);
            }
        }
        11 => {
            let folder = walk.mix(&[&inputs.photos], &[&inputs.empty, fifo.as_str(), "nope", &inputs.street]);
            push(&["photo-lut", folder]);
            push(&["-o", walk.mix(&["p.flut"], &["/sys/p.flut", "no/such/p.flut", "p.%070000d.flut"])]);
        }
        12 => {
            let plate = walk.mix(&[&inputs.street], &[&inputs.torn_exr, fifo.as_str(), "nope.exr", &inputs.lut]);
            push(&[
                "dof",
                plate,
                "--depth",
                walk.mix(&[&inputs.street_z], &[&inputs.torn_exr, fifo.as_str(), "nope.exr"]),
            ]);
            push(&["--device", walk.pick(&["cpu", "cpu", "auto"])]);
            push(&["-o", walk.mix(&["d.exr", "d.png"], &["/sys/d.exr", "no/such/d.exr", "d.%070000d.exr", "d.txt"])]);
            let optional: [(&str, &[&str]); 7] = [
                ("--focus-m", &["5", "0", "nan", "-1", "1e300"]),
                ("--focus-px", &["40,20", "1000000,5", "nan,1", "x"]),
                ("--f-number", &["2", "0", "nan", "1e300"]),
                ("--aperture", &["circle", "blades:6", "blades:1000000", "blades:nan", "image:nope.png"]),
                ("--method", &["live", "reference", "nope"]),
                ("--sensor-mm", &["36", "0", "nan", "1e300"]),
                ("--lens", &["heliar", "nope", &inputs.fifo]),
            ];
            for (flag, values) in optional {
                if walk.chance(20) {
                    push(&[flag, walk.pick(values)]);
                }
            }
        }
        _ => {
            // The smallest bench that bakes, traces and times (about 10 s), with hostile values among them.
            push(&["bench", "--lens", walk.mix(&["heliar"], &["nope", &inputs.fifo])]);
            push(&["--size", walk.mix(&["64x36"], &["0x0", "8192x8192", "x"])]);
            push(&["--grids", walk.mix(&["8"], &["0", "100000", "x"])]);
            push(&["--reference-grid", walk.mix(&["16"], &["0", "1000000"])]);
            push(&["--repeats", walk.mix(&["1"], &["0", "1000000000"])]);
            push(&["--lut-res", walk.mix(&["16"], &["0", "100000"])]);
            push(&["--theta-max", walk.mix(&["3"], &["nan", "1e300"])]);
            push(&["-o", walk.mix(&["b"], &["/sys/b", "no/such/b"])]);
            if walk.chance(20) {
                push(&["--update-readme", walk.pick(&["README.md", "/sys/README.md", &inputs.fifo])]);
            }
        }
    }
    args
}

#[test]
fn a_random_walk_over_the_command_line_ends_in_0_or_2_and_writes_finite_images() {
    let seed: u64 = std::env::var("FLARELAB_WALK_SEED").ok().and_then(|s| s.parse().ok()).unwrap_or(61);
    let runs: usize = std::env::var("FLARELAB_WALK_RUNS").ok().and_then(|s| s.parse().ok()).unwrap_or(160);
    let mut walk = Walk(seed.wrapping_mul(0x9e37_79b9_7f4a_7c15) | 1);
    let dir = tempfile::tempdir().unwrap();
    let inputs = Inputs::make(dir.path());
    let (mut zero, mut two, mut worst) = (0usize, 0usize, (0i64, Vec::<String>::new()));
    let mut failures = Vec::new();
    for k in 0..runs {
        let work = dir.path().join(format!("run{k}"));
        std::fs::create_dir_all(&work).unwrap();
        let args = command(&mut walk, &inputs);
        let ended = run(&args, &work, Duration::from_secs(120));
        let what = format!("run {k}: flarelab {}", args.join(" "));
        if std::env::var_os("FLARELAB_WALK_SAY").is_some() {
            let last = ended.stderr.trim().lines().last().unwrap_or("");
            println!("{what}: exit {:?}, {:.1} s, {} MB: {last}", ended.code, ended.seconds, ended.peak_rss_kb / 1024);
        }
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
            Some(2) => two += 1,
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
