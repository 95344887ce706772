//! The desktop app in a real (virtual) X window: it starts on the default lens and shows a flare. Run under
//! Xvfb when `xvfb-run` is installed (`.ci/run` installs it), skipped with the reason printed otherwise.
//!
//! Xvfb keeps its screen in a file (`-fbdir`, XWD format); the test copies it while the app runs, converts
//! it to PNG (`target/tmp/app_screenshot.png`, printed) and checks that the viewport shows light. Then the
//! app's drag bench (`FLARELAB_DRAG_BENCH`) sweeps the light for a few frames rendered at 1280x720
//! (`FLARELAB_VIEW_PX`) and prints its
//! median frame interval (reported, never asserted: machines are shared). `tests/screenshot.sh` runs this
//! test on a release build for a person to look at.

use std::path::Path;
use std::process::Command;

fn have_xvfb() -> bool {
    if Command::new("xvfb-run").arg("--help").output().is_err() {
        flare_core::render::gpu::skip_without_gpu(
            "xvfb-run is not installed (Debian package xvfb); the app needs a display to start",
        );
        return false;
    }
    true
}

/// A scratch home for the app and, inside it, the folder Xvfb keeps its screen in.
fn scratch() -> (tempfile::TempDir, std::path::PathBuf) {
    let dir = tempfile::tempdir().unwrap();
    let fb = dir.path().join("fb");
    std::fs::create_dir_all(&fb).unwrap();
    (dir, fb)
}

/// Runs `script` (sh) under a fresh Xvfb of `screen` with its framebuffer in `fbdir`; stdout + stderr.
fn under_xvfb(screen: &str, fbdir: &Path, home: &Path, script: &str) -> String {
    let out = Command::new("xvfb-run")
        .args(["-a", "-s", &format!("-screen 0 {screen} -fbdir {}", fbdir.display()), "sh", "-c", script])
        .env("XDG_RUNTIME_DIR", home)
        .env("HOME", home)
        .env("XDG_DATA_HOME", home.join("data"))
        .env("XDG_CONFIG_HOME", home.join("config"))
        .env("FLARELAB_FRESH", "1")
        .output()
        .expect("xvfb-run runs");
    format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr))
}

/// A ZPixmap XWD file of 24/32-bit TrueColor (what Xvfb writes) as RGB rows.
fn read_xwd(bytes: &[u8]) -> Result<image::RgbImage, String> {
    let field = |k: usize| -> Result<u32, String> {
        let b = bytes.get(4 * k..4 * k + 4).ok_or("the XWD header is truncated")?;
        Ok(u32::from_be_bytes([b[0], b[1], b[2], b[3]]))
    };
    let (header_size, format, width, height) = (field(0)?, field(2)?, field(4)?, field(5)?);
    let (byte_order, bits_per_pixel, bytes_per_line, ncolors) = (field(7)?, field(11)?, field(12)?, field(19)?);
    if format != 2 || bits_per_pixel != 32 {
        return Err(format!("XWD format {format}, {bits_per_pixel} bits per pixel: expected ZPixmap, 32"));
    }
    let (red_mask, green_mask, blue_mask) = (field(14)?, field(15)?, field(16)?);
    let start = header_size as usize + 12 * ncolors as usize;
    let mut img = image::RgbImage::new(width, height);
    let channel = |v: u32, mask: u32| ((v & mask) >> mask.trailing_zeros()) as u8;
    for y in 0..height {
        for x in 0..width {
            let at = start + y as usize * bytes_per_line as usize + 4 * x as usize;
            let p = bytes.get(at..at + 4).ok_or("the XWD pixels are truncated")?;
            let v = if byte_order == 0 {
                u32::from_le_bytes([p[0], p[1], p[2], p[3]])
            } else {
                u32::from_be_bytes([p[0], p[1], p[2], p[3]])
            };
            img.put_pixel(x, y, image::Rgb([channel(v, red_mask), channel(v, green_mask), channel(v, blue_mask)]));
        }
    }
    Ok(img)
}

#[test]
fn the_app_opens_on_the_default_lens_and_shows_a_flare() {
    if !have_xvfb() {
        return;
    }
    let (dir, fb) = scratch();
    let shot = dir.path().join("screen.xwd");
    let app = env!("CARGO_BIN_EXE_flarelab");
    // Start the app, give it time to draw (a debug build on lavapipe is slow), copy the screen, stop it.
    let script = format!(
        "'{app}' & P=$!; sleep 15; if kill -0 $P 2>/dev/null; then echo APP-ALIVE; cp '{}/Xvfb_screen0' '{}'; kill $P; fi; wait $P 2>/dev/null; true",
        fb.display(),
        shot.display()
    );
    let text = under_xvfb("1440x900x24", &fb, dir.path(), &script);
    assert!(text.contains("APP-ALIVE"), "the app did not stay open under Xvfb:\n{text}");
    assert!(!text.contains("panicked") && !text.contains("internal error"), "{text}");
    let img = read_xwd(&std::fs::read(&shot).unwrap()).unwrap();
    let out = Path::new(env!("CARGO_TARGET_TMPDIR")).join("app_screenshot.png");
    img.save(&out).unwrap();
    println!("screenshot: {}", out.display());
    // The viewport fills the top left of the window: it must show light, in more than a few shades (a
    // flare, not a flat placeholder).
    let (w, h) = (img.width(), img.height());
    let mut lit = 0;
    let mut shades = std::collections::HashSet::new();
    for y in h / 10..h / 2 {
        for x in w / 20..w / 2 {
            let p = img.get_pixel(x, y).0;
            if p.iter().map(|&c| u32::from(c)).sum::<u32>() > 90 {
                lit += 1;
            }
            shades.insert(p);
        }
    }
    let area = (h / 2 - h / 10) * (w / 2 - w / 20);
    assert!(lit > area / 10, "the viewport is dark: {lit} of {area} pixels lit (see {})", out.display());
    assert!(shades.len() > 200, "the viewport shows {} shades only (see {})", shades.len(), out.display());
}

#[test]
fn the_drag_bench_sweeps_the_light_and_reports_frame_times() {
    if !have_xvfb() {
        return;
    }
    let (dir, fb) = scratch();
    let app = env!("CARGO_BIN_EXE_flarelab");
    let frames = 20;
    for what in ["light", "exposure"] {
        let script = format!(
            "FLARELAB_AUTO_BAKE=0 FLARELAB_VIEW_PX=1280x720 FLARELAB_DRAG_BENCH={frames} FLARELAB_DRAG_BENCH_WHAT={what} timeout 120 '{app}'"
        );
        let text = under_xvfb("1280x720x24", &fb, dir.path(), &script);
        let line =
            text.lines().find(|l| l.starts_with("drag bench:")).unwrap_or_else(|| panic!("no bench line:\n{text}"));
        println!("{line}");
        assert!(line.contains(&format!("{what}: {frames} frames at 1280x720")), "{line}");
        // While it moves the viewport draws drafts (lavapipe: 1/4 resolution), then the full frame once it
        // lets go; lavapipe has timestamp queries, so the flare's GPU time is measured by the GPU.
        assert!(line.contains("drafts at 1/4 resolution drew a median"), "{line}");
        assert!(line.contains("ms after letting go"), "{line}");
        assert!(line.contains("ms of GPU time (llvmpipe"), "{line}");
        assert!(!text.contains("panicked"), "{text}");
        if what == "exposure" {
            // Sweeping the exposure rebuilds no optics and uploads no texture after the first frame.
            assert!(line.contains("0 optics rebuilds, 0 texture uploads"), "{line}");
        }
    }
}
