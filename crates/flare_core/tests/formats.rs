//! Lens files: lossless JSON round trips, the same lens through .zmx and .dat giving the same results, real
//! .zmx quirks (UTF-16, units, catalogue glasses), and hostile files refused with a reason that names the
//! line or field.

use std::path::Path;

use flare_core::files::write_atomic;
use flare_core::optics::formats::{
    FormatError, LensFormat, MAX_FILE_BYTES, decode_text, load_lens_file, parse_lens, parse_lens_bytes, pbrt, to_json,
    zmx,
};
use flare_core::optics::library::{BUILTIN_LENSES, builtin_lens, ids};
use flare_core::optics::{D_LINE_NM, FirstOrder, Lens, LightPath, TraceOptions, TraceStatus, Tracer, pupil_ray};

/// First-order data and the landings (or failures, as NaN-free codes) of a grid of rays along the image path
/// and two ghost paths, at the d-line.
fn fingerprint(lens: &Lens) -> Vec<f64> {
    let fo = FirstOrder::d_line(lens).unwrap();
    let mut out = vec![fo.efl_mm, fo.bfd_mm, fo.entrance_pupil_z_mm, fo.entrance_pupil_diameter_mm];
    let pairs = lens.ghost_pairs();
    let mut paths = vec![LightPath::image(lens)];
    for (i, j) in [pairs[0], pairs[pairs.len() - 1]] {
        paths.push(LightPath::ghost(lens, i, j).unwrap());
    }
    for path in &paths {
        let tracer = Tracer::new(lens, path, D_LINE_NM, fo.sensor_z_mm());
        for theta_deg in [0.0_f64, 7.0, 15.0] {
            for py in [-0.7, 0.0, 0.4] {
                let ray = pupil_ray(&fo.entrance_pupil(), theta_deg.to_radians(), 0.3, py);
                let result = tracer.trace(&ray, TraceOptions::default());
                match (result.status, result.sensor_point_mm) {
                    (TraceStatus::Landed, Some(p)) => out.extend([p.x, p.y]),
                    (status, _) => out.extend([-1.0e9, status.surface().map_or(-1.0, |s| s as f64)]),
                }
            }
        }
    }
    out
}

fn assert_close(a: &[f64], b: &[f64], tolerance_mm: f64, what: &str) {
    assert_eq!(a.len(), b.len(), "{what}");
    for (k, (x, y)) in a.iter().zip(b).enumerate() {
        assert!((x - y).abs() <= tolerance_mm * x.abs().max(1.0), "{what}: value {k}: {x} vs {y}");
    }
}

#[test]
fn json_round_trip_is_lossless() {
    for (id, text) in BUILTIN_LENSES {
        let lens = parse_lens(text, Some(LensFormat::Json), id).unwrap();
        let written = to_json(&lens);
        let original: serde_json::Value = serde_json::from_str(text).unwrap();
        let again: serde_json::Value = serde_json::from_str(&written).unwrap();
        assert_eq!(original, again, "{id}: JSON written back differs from the file");
        assert_eq!(parse_lens(&written, None, id).unwrap(), lens, "{id}");
    }
}

/// Coatings and unknown top-level keys come back as they were (with a warning naming the keys); an unknown
/// surface key is refused (a misspelled optional key would otherwise be dropped silently).
#[test]
fn json_keeps_unknown_keys_and_coatings() {
    let mut value: serde_json::Value = serde_json::from_str(BUILTIN_LENSES[0].1).unwrap();
    value["surfaces"][0]["coating"] = serde_json::json!({"type": "quarter_wave", "design_wavelength_nm": 550.0});
    value["surfaces"][1]["coating"] = serde_json::json!({"type": "multilayer", "layers": [{"index": 1.38, "thickness_nm": 99.6}, {"index": 2.1, "thickness_nm": 65.0}]});
    value["my_tool"] = serde_json::json!({"any": [1, 2, 3]});
    let text = serde_json::to_string(&value).unwrap();
    let lens = parse_lens(&text, None, "x").unwrap();
    let back: serde_json::Value = serde_json::from_str(&to_json(&lens)).unwrap();
    assert_eq!(back, value);
    value["surfaces"][2]["vendor_note"] = serde_json::json!("not a surface key");
    let e = parse_lens(&serde_json::to_string(&value).unwrap(), None, "x").unwrap_err().to_string();
    assert!(e.contains("unknown surface key `vendor_note`") && e.contains("surfaces[2]"), "{e}");
}

#[test]
fn zmx_and_dat_give_the_same_results_as_json() {
    for id in ids() {
        let lens = builtin_lens(id).unwrap();
        let reference = fingerprint(&lens);

        // .zmx stores curvature 1/R: radii come back to the last bit or within an ulp.
        let via_zmx = parse_lens(&zmx::write(&lens).unwrap(), Some(LensFormat::Zmx), id).unwrap();
        assert_eq!(via_zmx.surfaces.len(), lens.surfaces.len());
        for (a, b) in lens.surfaces.iter().zip(&via_zmx.surfaces) {
            assert!((a.radius_mm - b.radius_mm).abs() <= 1e-15 * a.radius_mm.abs(), "{id}: {a:?} vs {b:?}");
            assert_eq!(
                (a.thickness_mm.unwrap_or(0.0), &a.medium, a.semi_aperture_mm, a.stop),
                (b.thickness_mm.unwrap_or(0.0), &b.medium, b.semi_aperture_mm, b.stop),
                "{id}"
            );
            // Conic and aspheric terms (EVENASPH, CONI, PARM 1..8) come back exactly.
            assert_eq!((a.conic, a.aspheric_r2, &a.aspheric), (b.conic, b.aspheric_r2, &b.aspheric), "{id}");
        }
        assert_close(&reference, &fingerprint(&via_zmx), 1e-12, &format!("{id} via .zmx"));
        assert_eq!(LensFormat::detect(&zmx::write(&lens).unwrap()), Some(LensFormat::Zmx));
        assert_eq!(LensFormat::detect(&to_json(&lens)), Some(LensFormat::Json));

        // pbrt's table holds spheres only: an aspheric lens is refused, naming the surface.
        let dat = pbrt::write(&lens);
        if let Some(k) = lens.surfaces.iter().position(|s| !s.is_spherical()) {
            let e = dat.unwrap_err().to_string();
            let kind = lens.surfaces[k].non_spherical_kind().unwrap();
            assert!(e.contains(&format!("surface {k} is {kind}")), "{e}");
            continue;
        }
        let dat = dat.unwrap();
        // .dat keeps radius, thickness, n_d and aperture exactly: the d-line results are bit-identical.
        let via_dat = parse_lens(&dat, Some(LensFormat::PbrtDat), id).unwrap();
        assert_eq!(fingerprint(&via_dat), reference, "{id} via .dat");
        assert_eq!(LensFormat::detect(&dat), Some(LensFormat::PbrtDat));
    }
}

fn utf16(text: &str, little: bool, bom: bool) -> Vec<u8> {
    let mut bytes = Vec::new();
    if bom {
        bytes.extend(if little { [0xFF, 0xFE] } else { [0xFE, 0xFF] });
    }
    for unit in text.encode_utf16() {
        bytes.extend(if little { unit.to_le_bytes() } else { unit.to_be_bytes() });
    }
    bytes
}

#[test]
fn zmx_in_utf16_and_utf8_bom_reads_the_same() {
    let lens = builtin_lens("dgauss").unwrap();
    let text = zmx::write(&lens).unwrap().replace('\n', "\r\n");
    let expected = fingerprint(&lens);
    let mut with_bom = vec![0xEF, 0xBB, 0xBF];
    with_bom.extend(text.as_bytes());
    for (what, bytes) in [
        ("UTF-16 LE with BOM", utf16(&text, true, true)),
        ("UTF-16 BE with BOM", utf16(&text, false, true)),
        ("UTF-16 LE without BOM", utf16(&text, true, false)),
        ("UTF-8 with BOM", with_bom),
    ] {
        let read = parse_lens_bytes(&bytes, Path::new("double_gauss.zmx")).unwrap_or_else(|e| panic!("{what}: {e}"));
        assert_close(&expected, &fingerprint(&read), 1e-12, what);
    }
}

/// A file in the form OpticStudio writes, with cosmetic keywords, a catalogue glass without n_d, a model
/// glass, and lengths in inches.
const OPTICSTUDIO_SAMPLE: &str = r#"VERS 190000 123 456
MODE SEQ
NAME Singlet behind a stop, in inches
NOTE 0 a note
UNIT IN X W X CM MR CPMM
ENPD 1.0
FLOA
GCAT SCHOTT
SURF 0
  TYPE STANDARD
  CURV 0.0 0 0 0 0 ""
  HIDE 0 0 0 0 0 0 0 0 0 0
  MIRR 2 0
  SLAB 1
  DISZ INFINITY
SURF 1
  STOP
  TYPE STANDARD
  CURV 0.0 0 0 0 0 ""
  DISZ 0.2
  DIAM 0.25 1 0 0 1 ""
SURF 2
  COMM front
  TYPE STANDARD
  CURV 0.5 0 0 0 0 ""
  COAT AR
  DISZ 0.15
  GLAS N-BK7 0 0
  DIAM 0.4 1 0 0 1 ""
  CONI 0
  POPS 0 0 0 0 0 0 0 0 1 1 1 1 0 0 0 0
SURF 3
  TYPE STANDARD
  CURV -0.2 0 0 0 0 ""
  DISZ 0.05
  GLAS ___BLANK 1 0 1.72 29.3 0 0 0 0 0 0
  DIAM 0.4 1 0 0 1 ""
SURF 4
  TYPE STANDARD
  CURV 0.1 0 0 0 0 ""
  DISZ 2.5
  DIAM 0.4 1 0 0 1 ""
SURF 5
  TYPE STANDARD
  CURV 0.0
  DISZ 0
"#;

#[test]
fn opticstudio_sample_reads_with_units_and_glasses() {
    let lens = parse_lens(OPTICSTUDIO_SAMPLE, None, "singlet").unwrap();
    assert_eq!(lens.name, "Singlet behind a stop, in inches");
    assert_eq!(lens.surfaces.len(), 4);
    assert!(lens.surfaces[0].stop);
    let front = &lens.surfaces[1];
    assert!((front.radius_mm - 2.0 * 25.4).abs() < 1e-12, "CURV 0.5 per inch is R = 50.8 mm");
    assert!((front.thickness_mm.unwrap() - 0.15 * 25.4).abs() < 1e-12);
    assert!((front.semi_aperture_mm - 0.4 * 25.4).abs() < 1e-12, "DIAM is the semi-diameter");
    assert_eq!((front.medium.n_d, front.medium.glass.as_deref()), (1.5168, Some("N-BK7")), "catalogue glass");
    assert_eq!(
        (lens.surfaces[2].medium.n_d, lens.surfaces[2].medium.v_d, lens.surfaces[2].medium.glass.as_deref()),
        (1.72, Some(29.3), None)
    );
    assert!(lens.surfaces[3].medium.is_air());
    assert_eq!(lens.ghost_pairs().len(), 3);
    FirstOrder::d_line(&lens).unwrap();
}

/// A `GCAT` line picks the catalogue of a name two catalogues share: SCHOTT and CDGM both have F5, and
/// `GCAT CDGM` makes it CDGM's (kept as `CDGM:F5`, whose dispersion differs from SCHOTT's); the writer gives
/// the GCAT back, so the lens reads back with the same glass.
#[test]
fn a_gcat_line_picks_the_catalogue_of_a_shared_glass_name() {
    let schott = parse_lens(OPTICSTUDIO_SAMPLE.replace("GLAS N-BK7 0 0", "GLAS F5 0 0").as_str(), None, "s").unwrap();
    assert_eq!(schott.surfaces[1].medium.glass.as_deref(), Some("F5"), "GCAT SCHOTT: the plain name");
    let text = OPTICSTUDIO_SAMPLE.replace("GLAS N-BK7 0 0", "GLAS F5 0 0").replace("GCAT SCHOTT", "GCAT CDGM SCHOTT");
    let cdgm = parse_lens(&text, None, "c").unwrap();
    let medium = &cdgm.surfaces[1].medium;
    assert_eq!(medium.glass.as_deref(), Some("CDGM:F5"));
    assert_eq!(medium.dispersion().describe(), "CDGM F5 (AGF formula 1)");
    assert_ne!(medium.index_at(450.0), schott.surfaces[1].medium.index_at(450.0), "two different curves");
    let written = flare_core::optics::formats::zmx::write(&cdgm).unwrap();
    assert!(written.contains("GCAT CDGM\n") && written.contains("GLAS F5 "), "{written}");
    let back = parse_lens(&written, None, "c").unwrap();
    assert_eq!(back.surfaces[1].medium.glass.as_deref(), Some("CDGM:F5"));
}

/// Loads `text` as a file called `name` and returns the error message.
fn refusal(name: &str, bytes: &[u8]) -> String {
    match parse_lens_bytes(bytes, Path::new(name)) {
        Ok(lens) => panic!("{name} was accepted: {lens:?}"),
        Err(e) => e.to_string(),
    }
}

fn heliar_json_with(edit: impl FnOnce(&mut serde_json::Value)) -> Vec<u8> {
    let mut v: serde_json::Value = serde_json::from_str(BUILTIN_LENSES[0].1).unwrap();
    edit(&mut v);
    serde_json::to_vec_pretty(&v).unwrap()
}

#[test]
fn hostile_json_files_are_refused_with_the_reason() {
    let text = BUILTIN_LENSES[0].1;
    let cases: Vec<(&str, Vec<u8>, &[&str])> = vec![
        ("empty", vec![], &["empty"]),
        ("blank", b"  \n\t \n".to_vec(), &["empty"]),
        ("truncated", text.as_bytes()[..text.len() / 2].to_vec(), &["JSON line", "EOF"]),
        ("garbage", (0..4000u32).map(|i| (i.wrapping_mul(2_654_435_761) >> 13) as u8).collect(), &["not text"]),
        (
            "wrong type",
            heliar_json_with(|v| v["surfaces"][3]["radius"] = "thirty".into()),
            &["surfaces[3].radius", "invalid type"],
        ),
        (
            "missing field",
            heliar_json_with(|v| {
                v["surfaces"][2].as_object_mut().unwrap().remove("nd");
            }),
            &["surfaces[2]", "nd"],
        ),
        ("surfaces not a list", heliar_json_with(|v| v["surfaces"] = 7.into()), &["surfaces", "invalid type"]),
        ("no surfaces", heliar_json_with(|v| v["surfaces"] = serde_json::json!([])), &["no surfaces"]),
        (
            "negative thickness",
            heliar_json_with(|v| v["surfaces"][1]["thickness"] = (-1.0).into()),
            &["surface 1", "thickness", "negative"],
        ),
        ("index below one", heliar_json_with(|v| v["surfaces"][0]["nd"] = 0.7.into()), &["surface 0", "nd", "below 1"]),
        (
            "radius inside aperture",
            heliar_json_with(|v| v["surfaces"][0]["radius"] = 10.0.into()),
            &["surface 0", "radius", "smaller than the semi-aperture"],
        ),
        ("no stop", heliar_json_with(|v| v["surfaces"][5]["stop"] = false.into()), &["no aperture stop"]),
        (
            "two stops",
            heliar_json_with(|v| {
                v["surfaces"][6]["stop"] = true.into();
            }),
            &["2 aperture stops", "[5, 6]"],
        ),
        (
            "a stop narrower than its sphere",
            heliar_json_with(|v| v["surfaces"][5]["radius"] = 10.0.into()),
            &["surface 5", "radius", "|10| mm is smaller than the semi-aperture 11.6 mm"],
        ),
        (
            "absurd thickness",
            heliar_json_with(|v| v["surfaces"][2]["thickness"] = 1e12.into()),
            &["surface 2", "thickness", "absurd"],
        ),
        ("absurd index", heliar_json_with(|v| v["surfaces"][0]["nd"] = 12.0.into()), &["surface 0", "nd", "absurd"]),
        (
            "negative aperture",
            heliar_json_with(|v| v["surfaces"][4]["semi_aperture"] = (-3.0).into()),
            &["surface 4", "semi_aperture", "positive"],
        ),
        ("bad abbe", heliar_json_with(|v| v["surfaces"][0]["vd"] = (-5.0).into()), &["surface 0", "vd"]),
        (
            "crossing surfaces",
            heliar_json_with(|v| v["surfaces"][0]["thickness"] = 1.0.into()),
            &["surface 0", "surfaces 0 and 1 meet at a height of", "on-axis light"],
        ),
        (
            "image space in glass",
            heliar_json_with(|v| v["surfaces"][8]["nd"] = 1.5.into()),
            &["surface 8", "image space"],
        ),
        ("units", heliar_json_with(|v| v["units"] = "inch".into()), &["units"]),
        ("object index", heliar_json_with(|v| v["object_index"] = 1.33.into()), &["object_index"]),
        (
            "bad coating",
            heliar_json_with(|v| {
                v["surfaces"][0]["coating"] = serde_json::json!({"type": "quarter_wave", "design_wavelength_nm": -5.0})
            }),
            &["surface 0", "coating.design_wavelength_nm"],
        ),
        (
            "trailing junk",
            {
                let mut b = text.as_bytes().to_vec();
                b.extend(b"}}");
                b
            },
            &["trailing"],
        ),
    ];
    for (what, bytes, expect) in cases {
        let message = refusal("lens.json", &bytes);
        for word in expect {
            assert!(message.contains(word), "{what}: message `{message}` does not mention `{word}`");
        }
        assert!(!message.contains('\n'), "{what}: one line please: {message}");
    }
}

#[test]
fn hostile_zmx_and_dat_files_name_the_line() {
    let sample = OPTICSTUDIO_SAMPLE;
    let cases: Vec<(&str, String, &[&str])> = vec![
        (
            "other surface type",
            sample.replace("SURF 3\n  TYPE STANDARD", "SURF 3\n  TYPE SZERNSAG"),
            &["line 33", "TYPE SZERNSAG", "not supported"],
        ),
        (
            "conic beyond its rim",
            sample.replace("CONI 0", "CONI 30"),
            &["line 22", "surface 1", "conic", "defined up to a height of 9.12 mm", "10.16 mm"],
        ),
        ("PARM on a standard surface", sample.replace("  CONI 0", "  PARM 2 0.001"), &["line 30", "PARM", "STANDARD"]),
        ("mirror", sample.replace("GLAS N-BK7 0 0", "GLAS MIRROR 0 0"), &["line 28", "MIRROR"]),
        (
            "unknown glass",
            sample.replace("GLAS N-BK7 0 0", "GLAS UNOBTAINIUM 0 0"),
            &["line 28", "UNOBTAINIUM", "catalogue"],
        ),
        ("not a number", sample.replace("CURV -0.2", "CURV -0.2x"), &["line 34", "CURV", "not a number"]),
        ("nan", sample.replace("DISZ 0.05", "DISZ nan"), &["line 35", "not finite"]),
        ("non-sequential", sample.replace("MODE SEQ", "MODE NSC"), &["line 2", "NSC"]),
        ("square aperture", sample.replace("  POPS", "  SQAP 1 1\n  POPS"), &["line 31", "SQAP"]),
        ("glass index below one", sample.replace("1.72 29.3", "0.72 29.3"), &["line 32", "surface 2", "nd"]),
        ("missing DIAM", sample.replace("  DIAM 0.4 1 0 0 1 \"\"\nSURF 4", "SURF 4"), &["line 32", "DIAM"]),
        ("no stop", sample.replace("  STOP\n", ""), &["no aperture stop"]),
        ("only the object", "VERS 1\nSURF 0\n  DISZ INFINITY\n".to_owned(), &["SURF blocks"]),
        // Issue 33: the last of two values silently won (EFL 99 -> 49 mm).
        ("curvature twice", sample.replace("CURV -0.2", "CURV -0.2\n  CURV -0.4"), &["CURV repeated", "first on line"]),
        ("glass twice", sample.replace("GLAS N-BK7 0 0", "GLAS N-BK7 0 0\n  GLAS F5 0 0"), &["GLAS repeated"]),
    ];
    for (what, text, expect) in cases {
        let message = refusal("lens.zmx", text.as_bytes());
        for word in expect {
            assert!(message.contains(word), "{what}: message `{message}` does not mention `{word}`");
        }
    }
    let dat = pbrt::write(&builtin_lens("dgauss").unwrap()).unwrap();
    let dat_cases: Vec<(&str, String, &[&str])> = vec![
        ("three columns", dat.replacen("84.83\t0.12\t1\t25.2", "84.83\t0.12\t1", 1), &["line 4", "expected 4 numbers"]),
        ("letters", dat.replacen("84.83", "84.8e", 1), &["line 4", "radius", "84.8e"]),
        ("two stops", dat.replacen("-20.385\t0.19\t1\t20", "0\t0.19\t0\t20", 1), &["2 aperture stops"]),
    ];
    for (what, text, expect) in dat_cases {
        let message = refusal("lens.dat", text.as_bytes());
        for word in expect {
            assert!(message.contains(word), "{what}: message `{message}` does not mention `{word}`\n{text}");
        }
    }
    assert!(refusal("lens.txt", b"hello world\nthis is not a lens\n").contains("not a lens file"));
}

#[test]
fn huge_and_missing_files_are_refused_before_reading() {
    let dir = tempfile::tempdir().unwrap();
    let huge = dir.path().join("huge.json");
    let file = std::fs::File::create(&huge).unwrap();
    file.set_len(MAX_FILE_BYTES + 1).unwrap();
    assert!(matches!(load_lens_file(&huge), Err(FormatError::TooLarge { .. })));
    let missing = load_lens_file(&dir.path().join("nope.zmx")).unwrap_err().to_string();
    assert!(missing.contains("nope.zmx"), "{missing}");
}

#[test]
fn atomic_write_replaces_whole_files_only() {
    let dir = tempfile::tempdir().unwrap();
    let target = dir.path().join("lens.json");
    std::fs::write(&target, "old").unwrap();
    let lens = builtin_lens("tessar").unwrap();
    write_atomic(&target, to_json(&lens).as_bytes()).unwrap();
    assert_eq!(load_lens_file(&target).unwrap(), lens);
    let leftovers: Vec<_> = std::fs::read_dir(dir.path()).unwrap().collect();
    assert_eq!(leftovers.len(), 1, "no temporary file is left behind");
    // Writing into a folder that does not exist fails and leaves nothing.
    assert!(write_atomic(&dir.path().join("no/such/dir/x.json"), b"{}").is_err());
    // The replaced file keeps its permissions; a new one is readable by others as usual (not the temporary
    // file's private 0600).
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        let mode = |p: &std::path::Path| std::fs::metadata(p).unwrap().permissions().mode() & 0o777;
        std::fs::set_permissions(&target, std::fs::Permissions::from_mode(0o640)).unwrap();
        write_atomic(&target, b"again").unwrap();
        assert_eq!(mode(&target), 0o640);
        let fresh = dir.path().join("new.png");
        write_atomic(&fresh, b"new").unwrap();
        assert_eq!(mode(&fresh), 0o644);
    }
}

#[test]
fn decoding_refuses_binary_and_accepts_latin1() {
    assert!(matches!(decode_text(&[0x7F, 0x45, 0x4C, 0x46, 0, 1, 2, 3]), Err(FormatError::NotText { .. })));
    let latin1 = b"# Objektiv f\xfcr Test\n50 5 1.5 20\n-200 5 1 20\n0 40 0 10\n";
    let text = decode_text(latin1).unwrap();
    assert!(text.contains("für"));
    let lens = parse_lens(&text, None, "latin").unwrap();
    assert_eq!(lens.name, "Objektiv für Test");
}
