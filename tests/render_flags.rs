//! `flarelab render`'s flags stay what they were while their code changes shape: the same flags (names, short
//! forms, aliases, defaults, whether they take a value, which are hidden), and for a set of command lines the
//! same parsed document (`cli::render::document`, as JSON), the same other settings, and the same refusals,
//! word for word.
//!
//! The expected answers are `tests/data/render_flags.json`, written once by the code before (run with
//! `FLARELAB_BLESS=1` to write it again after a deliberate change, and say why in the commit).

use clap::{CommandFactory, Parser};
use flarelab::cli::render::{RenderArgs, document};
use flarelab::cli::{Cli, Command};
use serde_json::{Value, json};

/// Command lines after `flarelab render`, covering every flag that sets a field of the document, every other
/// flag, and the refusals that name a flag.
const LINES: &[&str] = &[
    "-o out.png",
    "dgauss -o out.png",
    "--preset heliar-portrait -o out.exr",
    "--preset heliar-portrait --f-number 8 --coating broadband -o out.exr",
    "--preset zoom-sun-sweep --frames 1-48 --log log.json --skip-existing -o out/f.####.exr",
    "tessar --light-deg 6,-3 --size 640x360 --aperture blades:7:15:0.5 --spectrum 7 -o t.png",
    "--exposure-ev auto -o out.png",
    "--exposure-ev 7.5 --plate-ev -1 --starburst-ev -2 --no-starburst -o out.png",
    "--tonemap aces -o out.png",
    "--tonemap none --ocio-config ocio://studio-config-latest --display sRGB --look x,y -o out.png",
    "--display P3-D65 -o out.png",
    "--view ACES --input-space display -o out.png",
    "--cube grade.cube -o out.png",
    "--desqueeze 1.5 --sensor-mm 24.9 -o out.png",
    "--dirt dust:7 --dirt-amount 0.05 --dirt-spread-deg 12 -o out.png",
    "--dirt haze -o out.png",
    "--background plates/p.####.exr --light auto --light-threshold 2 --light-power 100 --light-smooth 5 \
     --frames 1-10 -o out/f.####.exr",
    "--light keys --track track.csv --frame 3 -o out.png",
    "--shutter-deg 180 -o out.exr",
    "--exr-type float --exr-compression piz --layers ghosts -o out.exr",
    "--exr-type half --exr-compression none -o out.exr",
    "--depth z.exr --depth-range 1:100 --focus-px 3,4 --dof-method reference --axial-colour -o out.exr",
    "--depth z.exr --focus-m 5 -o out.exr",
    "--preset default --no-dof -o out.png",
    "--threshold 0.001 --accumulation-divisor 2 --device cpu -o out.png",
    "--method blended --lut zoom.flut --blend smooth:5:15 -o out.png",
    "--method raygrid --grid 64 --gpu-samples 2 --timings -o out.png",
    "--method reference --device gpu -o out.png",
    "--output out.png",
    // Refusals, each naming the flag that set the value.
    "--spectrum 99 -o out.png",
    "--exposure-ev 1000 -o out.png",
    "--plate-ev 1e9 -o out.png",
    "--starburst-ev 999 -o out.png",
    "--desqueeze 9 -o out.png",
    "--desqueeze auto -o out.png",
    "--desqueeze wide -o out.png",
    "--dirt-amount 2 --dirt dust -o out.png",
    "--dirt-spread-deg 0.01 --dirt dust -o out.png",
    "--dirt image:/no/such/dirt.png -o out.png",
    "--aperture blades:2 -o out.png",
    "--aperture blades:6:0:7 -o out.png",
    "--aperture star -o out.png",
    "--f-number 0.01 -o out.png",
    "--threshold -1 -o out.png",
    "--threshold 2 -o out.png",
    "--sensor-mm 0 -o out.png",
    "--light auto --light-threshold 0 -o out.png",
    "--light auto --light-power 0 -o out.png",
    "--depth z.exr --focus-m 0 -o out.png",
    "--depth z.exr --focus-px 3,4 --focus-m 2 -o out.png",
    "--sensor-mm -3 -o out.png",
    "--light-threshold 2 -o out.png",
    "--light auto --light-threshold -5 -o out.png",
    "--light auto --light-power -1 -o out.png",
    "--light auto --light-smooth 4 -o out.png",
    "--shutter-deg 900 -o out.png",
    "--depth z.exr --focus-m -2 -o out.png",
    "--blend sideways -o out.png",
    "--exposure 2 -o out.png",
    "--coating gold -o out.png",
    "no_such_lens -o out.png",
    "--preset no-such-look -o out.png",
    // Refused by the parser.
    "--frames 5-1 -o out/f.####.exr",
    "--frame 2 --frames 1-3 -o out.png",
    "--light-deg 1 -o out.png",
    "--size 10 -o out.png",
    "--method sideways -o out.png",
    "--light-deg 1,2",
];

/// What parsing and `document` make of one command line.
fn answer(line: &str) -> Value {
    let mut words = vec!["flarelab", "render"];
    words.extend(line.split_whitespace());
    let args = match Cli::try_parse_from(&words) {
        Ok(Cli { command: Some(Command::Render(args)), .. }) => args,
        Ok(other) => panic!("{line}: parsed as {other:?}"),
        Err(e) => return json!({ "parse_error": format!("{:?}", e.kind()) }),
    };
    let settings = others(&args);
    match document(&args) {
        Ok(doc) => {
            let mut value = serde_json::to_value(&doc).expect("a document serialises");
            // The lens by its id and a hash of its prescription: the file stays small, a change still shows.
            let lens = serde_json::to_string(&value["lens"]).unwrap();
            value["lens"] = json!(format!(
                "{} {:016x}",
                doc.lens.id,
                flare_core::fingerprint::fnv1a(lens.as_bytes(), flare_core::fingerprint::FNV_OFFSET)
            ));
            json!({ "document": value, "settings": settings })
        }
        Err(e) => json!({ "error": format!("{e:#}"), "settings": settings }),
    }
}

/// The settings of `args` that are not the document's.
fn others(args: &RenderArgs) -> Value {
    json!({
        "size": format!("{:?}", args.output.size),
        "frames": format!("{:?}", args.shot.frames),
        "frame": format!("{:?}", args.shot.frame),
        "light": format!("{:?}", args.light.source),
        "track": format!("{:?}", args.light.track),
        "log": format!("{:?}", args.shot.log),
        "skip_existing": args.shot.skip_existing,
        "frames_in_turn": args.shot.frames_in_turn,
        "timings": args.output.timings,
        "method": format!("{:?}", args.method.kind),
        "lut": format!("{:?}", args.method.lut),
        "grid": format!("{:?}", args.method.grid),
        "gpu_samples": args.method.gpu_samples,
        "accumulation_divisor": args.method.accumulation_divisor,
        "device": format!("{:?}", args.method.device),
        "layers": format!("{:?}", args.output.layers),
        "out": format!("{:?}", args.output.out),
    })
}

/// Every flag of `flarelab render`: its name, short form, aliases, defaults, whether it takes a value and
/// whether `--help` hides it.
fn flags() -> Value {
    let cli = Cli::command();
    let render = cli.find_subcommand("render").expect("render");
    let mut flags: Vec<Value> = render
        .get_arguments()
        .map(|a| {
            // A flag by its name (its field may move), a positional argument by its id.
            let name = a.get_long().map(|l| format!("--{l}")).unwrap_or_else(|| a.get_id().to_string());
            json!({
                "name": name,
                "short": a.get_short().map(String::from),
                "aliases": a.get_all_aliases().unwrap_or_default(),
                "defaults": a.get_default_values().iter().map(|v| v.to_string_lossy().into_owned()).collect::<Vec<_>>(),
                "takes_value": a.get_action().takes_values(),
                "hidden": a.is_hide_set(),
                "positional": a.is_positional(),
            })
        })
        .collect();
    flags.sort_by_key(|f| f["name"].as_str().unwrap_or("").to_owned());
    Value::Array(flags)
}

#[test]
fn render_s_flags_and_documents_are_what_they_were() {
    let now = json!({
        "flags": flags(),
        "lines": LINES.iter().map(|l| json!({ "line": l, "answer": answer(l) })).collect::<Vec<_>>(),
    });
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/render_flags.json");
    if std::env::var_os("FLARELAB_BLESS").is_some() {
        std::fs::write(&path, serde_json::to_string_pretty(&now).unwrap() + "\n").unwrap();
        eprintln!("wrote {}", path.display());
        return;
    }
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let before: Value = serde_json::from_str(&text).unwrap();
    assert_eq!(now["flags"], before["flags"], "the flags of `flarelab render` changed");
    let (now_lines, before_lines) = (now["lines"].as_array().unwrap(), before["lines"].as_array().unwrap());
    assert_eq!(now_lines.len(), before_lines.len(), "the command lines changed: bless them again");
    for (a, b) in now_lines.iter().zip(before_lines) {
        assert_eq!(a["line"], b["line"]);
        assert_eq!(
            a["answer"],
            b["answer"],
            "flarelab render {}: now\n{}\nbefore\n{}",
            a["line"],
            serde_json::to_string_pretty(&a["answer"]).unwrap(),
            serde_json::to_string_pretty(&b["answer"]).unwrap()
        );
    }
    // The set reaches the document (every line a document or a refusal, refusals that name their flag).
    let refusals = now_lines.iter().filter(|l| l["answer"].get("error").is_some()).count();
    let documents = now_lines.iter().filter(|l| l["answer"].get("document").is_some()).count();
    assert!(refusals >= 20 && documents >= 25, "{refusals} refusals, {documents} documents");
}

/// clap's own checks of the whole command line (unique ids, conflicts naming real flags, ...), which a release
/// build does not make.
#[test]
fn the_command_line_is_well_formed() {
    Cli::command().debug_assert();
}

/// `render --help` in its groups, each under its heading, in the order a user sets a frame up.
#[test]
fn render_s_help_is_in_groups() {
    let mut cli = Cli::command();
    let help = cli.find_subcommand_mut("render").expect("render").render_long_help().to_string();
    let headings =
        ["Optics:", "Light:", "Look:", "Camera:", "Colour:", "Shot:", "Depth of field:", "Method:", "Output:"];
    let at: Vec<usize> = headings
        .iter()
        .map(|h| help.find(&format!("\n{h}\n")).unwrap_or_else(|| panic!("no {h} in\n{help}")))
        .collect();
    assert!(at.windows(2).all(|w| w[0] < w[1]), "headings out of order:\n{help}");
    // Each flag under its own group's heading.
    let under = |flag: &str, heading: &str| {
        // The flag's own line (not the usage line's mention).
        let f = [format!("      --{flag} "), format!("      --{flag}\n"), format!("  -o, --{flag} ")]
            .iter()
            .find_map(|line| help.find(line.as_str()))
            .expect(flag);
        let h = headings.iter().position(|x| *x == heading).unwrap();
        at[h] < f && at.get(h + 1).is_none_or(|&next| f < next)
    };
    for (flag, heading) in [
        ("preset", "Optics:"),
        ("f-number", "Optics:"),
        ("aperture", "Optics:"),
        ("light-deg", "Light:"),
        ("light-smooth", "Light:"),
        ("exposure-ev", "Look:"),
        ("dirt", "Look:"),
        ("shutter-deg", "Camera:"),
        ("ocio-config", "Colour:"),
        ("frames", "Shot:"),
        ("focus-m", "Depth of field:"),
        ("method", "Method:"),
        ("device", "Method:"),
        ("out", "Output:"),
        ("exr-type", "Output:"),
    ] {
        assert!(under(flag, heading), "--{flag} is not under {heading}\n{help}");
    }
}

/// The plate-light flags tune a preset's own light found in the plate (they once went unread unless `--light
/// auto` was given too), and are refused, naming them, where the document finds no light.
#[test]
fn the_light_flags_tune_a_preset_s_found_light() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("found.json");
    let preset = flare_core::preset::Document { auto_light: Some(Default::default()), ..Default::default() };
    preset.save(&path).unwrap();
    let parse = |extra: &[&str]| {
        let mut words = vec!["flarelab", "render", "--preset", path.to_str().unwrap(), "-o", "x.png"];
        words.extend(extra);
        match Cli::try_parse_from(&words).unwrap().command {
            Some(Command::Render(args)) => document(&args),
            other => panic!("{other:?}"),
        }
    };
    let doc = parse(&["--light-threshold", "2", "--light-power", "50", "--light-smooth", "3"]).unwrap();
    let light = doc.auto_light.expect("the preset's light");
    assert_eq!((light.threshold, light.reference_power, light.smooth_frames), (2.0, Some(50.0), 3));
    let refused = parse(&["--light", "keys", "--light-smooth", "3"]).unwrap_err().to_string();
    assert!(refused.contains("apply to --light auto"), "{refused}");
}
