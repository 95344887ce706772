//! What lens designers bring: even aspheres and conics from `.zmx` and JSON (units, the r^2 term), the system
//! aperture of a `.zmx` (ENPD, FNUM, FLOA: which wins, said once), tolerant loading of transcriptions whose
//! guessed clear apertures cross (the Nikon of Hullin et al. as transcribed), and refusals with the line and
//! the reason.

use std::path::Path;

use flare_core::optics::formats::{LensFormat, read_lens, read_lens_bytes};
use flare_core::optics::library::builtin_lens;
use flare_core::optics::trace::{intersect_shape, shape_normal};
use flare_core::optics::{
    D_LINE_NM, FirstOrder, Lens, LightPath, Surface, TraceOptions, TraceStatus, Tracer, pupil_ray,
};
use glam::DVec3;

/// A singlet behind a stop, in inches, whose second surface is an even asphere with every PARM.
const ASPHERE_ZMX: &str = r#"VERS 190000 123 456
MODE SEQ
NAME Aspheric singlet, in inches
UNIT IN X W X CM MR CPMM
ENPD 0.5
SURF 0
  TYPE STANDARD
  CURV 0.0
  DISZ INFINITY
SURF 1
  STOP
  TYPE STANDARD
  CURV 0.0
  DISZ 0.2
  DIAM 0.3 1 0 0 1 ""
SURF 2
  TYPE EVENASPH
  CURV 0.5 0 0 0 0 ""
  CONI -0.6
  PARM 1 0.01
  PARM 2 -0.002
  PARM 3 0.0003
  PARM 4 0
  PARM 5 0
  PARM 6 0
  PARM 7 0
  PARM 8 0
  DISZ 0.15
  GLAS ___BLANK 1 0 1.5168 64.17 0 0 0 0 0 0
  DIAM 0.4 1 0 0 1 ""
SURF 3
  TYPE STANDARD
  CURV -0.1 0 0 0 0 ""
  DISZ 2.5
  DIAM 0.4 1 0 0 1 ""
SURF 4
  TYPE STANDARD
  CURV 0.0
  DISZ 0
"#;

fn read_zmx(text: &str) -> Result<flare_core::optics::formats::LoadedLens, String> {
    read_lens(text, Some(LensFormat::Zmx), "x").map_err(|e| e.to_string())
}

#[test]
fn an_even_asphere_reads_with_its_units_and_writes_back() {
    let loaded = read_zmx(ASPHERE_ZMX).unwrap();
    let s = &loaded.lens.surfaces[1];
    let inch = 25.4;
    assert!((s.radius_mm - 2.0 * inch).abs() < 1e-12);
    assert_eq!(s.conic, -0.6, "CONI has no unit");
    // PARM n multiplies r^(2n): it scales by inch^(1 - 2n).
    assert!((s.aspheric_r2 - 0.01 / inch).abs() < 1e-18, "{}", s.aspheric_r2);
    assert_eq!(s.aspheric.len(), 2, "trailing zero terms are dropped: {:?}", s.aspheric);
    assert!((s.aspheric[0] - -0.002 / inch.powi(3)).abs() < 1e-18);
    assert!((s.aspheric[1] - 0.0003 / inch.powi(5)).abs() < 1e-20);
    // The sag in millimetres equals the sag in inches times 25.4.
    let (h_in, c_in) = (0.3f64, 0.5f64);
    let sag_in = c_in * h_in * h_in / (1.0 + (1.0 - 0.4 * c_in * c_in * h_in * h_in).sqrt()) + 0.01 * h_in.powi(2)
        - 0.002 * h_in.powi(4)
        + 0.0003 * h_in.powi(6);
    assert!((s.sag_mm(h_in * inch).unwrap() - sag_in * inch).abs() < 1e-12);
    // Paraxial optics sees the vertex curvature c + 2 A2.
    assert!((s.vertex_curvature_per_mm() - (1.0 / (2.0 * inch) + 2.0 * 0.01 / inch)).abs() < 1e-15);

    // Written as a .zmx (EVENASPH, CONI, PARM 1..8) and as JSON, it reads back to the same surface.
    let zmx = flare_core::optics::formats::zmx::write(&loaded.lens).unwrap();
    assert!(zmx.contains("TYPE EVENASPH") && zmx.contains("CONI -0.6") && zmx.contains("PARM 1 "), "{zmx}");
    let again = read_zmx(&zmx).unwrap().lens;
    assert_eq!(again.surfaces[1].conic, s.conic);
    assert!((again.surfaces[1].aspheric_r2 - s.aspheric_r2).abs() <= 1e-15 * s.aspheric_r2.abs());
    let json = flare_core::optics::formats::to_json(&loaded.lens);
    assert!(json.contains("\"conic\": -0.6") && json.contains("\"aspheric_r2\""), "{json}");
    let from_json = read_lens(&json, None, "x").unwrap().lens;
    assert_eq!(from_json.surfaces, loaded.lens.surfaces);
}

#[test]
fn enpd_and_fnum_size_the_stop_and_say_which_won() {
    // ENPD 0.5 in = 12.7 mm: the stop sits in front of the lens, so its semi-diameter is 6.35 mm (the DIAM
    // of 0.3 in = 7.62 mm was a placeholder).
    let loaded = read_zmx(ASPHERE_ZMX).unwrap();
    let fo = FirstOrder::d_line(&loaded.lens).unwrap();
    assert!((fo.entrance_pupil_diameter_mm - 12.7).abs() < 1e-9, "{}", fo.entrance_pupil_diameter_mm);
    assert!((loaded.lens.surfaces[0].semi_aperture_mm - 6.35).abs() < 1e-9);
    assert_eq!(loaded.warnings.len(), 1, "{:?}", loaded.warnings);
    let w = &loaded.warnings[0];
    assert!(w.contains("ENPD 12.7 mm") && w.contains("6.35 mm") && w.contains("DIAM said 7.62 mm"), "{w}");

    // FNUM F: the entrance pupil is EFL / F.
    let fnum = ASPHERE_ZMX.replace("ENPD 0.5", "FNUM 8 0");
    let loaded = read_zmx(&fnum).unwrap();
    let fo = FirstOrder::d_line(&loaded.lens).unwrap();
    assert!((fo.f_number - 8.0).abs() < 1e-9, "{}", fo.f_number);
    assert!(loaded.warnings[0].contains("FNUM 8"), "{:?}", loaded.warnings);

    // Both: ENPD wins, and the FNUM it beat is named with its line.
    let both = ASPHERE_ZMX.replace("ENPD 0.5", "FNUM 8 0\nENPD 0.5");
    let loaded = read_zmx(&both).unwrap();
    assert!((FirstOrder::d_line(&loaded.lens).unwrap().entrance_pupil_diameter_mm - 12.7).abs() < 1e-9);
    assert!(loaded.warnings.iter().any(|w| w.contains("FNUM 8 (line 5) is ignored: ENPD 12.7 mm (line 6) wins")));

    // FLOA (float by stop size): the stop's DIAM is the aperture, and the ENPD kept in the file is ignored.
    let float = ASPHERE_ZMX.replace("ENPD 0.5", "ENPD 0.5\nFLOA");
    let loaded = read_zmx(&float).unwrap();
    assert!((loaded.lens.surfaces[0].semi_aperture_mm - 0.3 * 25.4).abs() < 1e-12);
    assert_eq!(loaded.warnings, vec!["the system aperture ENPD 12.7 mm (line 5) is ignored: FLOA (line 6) wins"]);
}

#[test]
fn aspheric_refusals_name_the_line_and_the_reason() {
    let cases: Vec<(&str, String, &[&str])> = vec![
        (
            // 1 - (1 + k) c^2 h^2 < 0 inside the clear aperture: the sag is not defined there.
            "conic undefined inside the aperture",
            ASPHERE_ZMX.replace("CONI -0.6", "CONI 30"),
            &["line 16", "surface 1", "conic", "defined up to a height of", "clear semi-aperture 10.16 mm"],
        ),
        ("term not a number", ASPHERE_ZMX.replace("PARM 2 -0.002", "PARM 2 x"), &["line 21", "PARM 2 value `x`"]),
        ("PARM beyond 8", ASPHERE_ZMX.replace("PARM 8 0", "PARM 8 0\n  PARM 9 1"), &["line 28", "PARM 9"]),
        (
            "PARM on STANDARD",
            ASPHERE_ZMX.replace("CURV -0.1", "CURV -0.1\n  PARM 2 0.1"),
            &["line 34", "PARM 2 = 0.1", "STANDARD"],
        ),
        ("negative ENPD", ASPHERE_ZMX.replace("ENPD 0.5", "ENPD -1"), &["line 5", "ENPD", "positive"]),
    ];
    for (what, text, expect) in cases {
        let message = match read_zmx(&text) {
            Ok(l) => panic!("{what}: accepted {:?}", l.lens.surfaces[1]),
            Err(e) => e,
        };
        for word in expect {
            assert!(message.contains(word), "{what}: `{message}` does not mention `{word}`");
        }
        assert!(!message.contains("e-1"), "{what}: numbers for people: {message}");
    }
    // JSON: too many terms, and a conic whose sag ends inside the aperture, each named by surface and field.
    let mut lens = builtin_lens("aspheric_zoom").unwrap();
    lens.surfaces[13].aspheric = vec![1e-9; 8];
    assert!(lens.validate().unwrap_err().to_string().contains("surface 13, field `aspheric`: 8 terms"));
    let mut lens = builtin_lens("aspheric_zoom").unwrap();
    lens.surfaces[14].aspheric = vec![1e306];
    let e = lens.validate().unwrap_err().to_string();
    assert!(e.contains("surface 14, field `aspheric`: the sag is not finite at a height of"), "{e}");
    let mut lens = builtin_lens("aspheric_zoom").unwrap();
    lens.surfaces[11].conic = 100.0;
    let e = lens.validate().unwrap_err().to_string();
    assert!(e.contains("surface 11, field `conic`") && e.contains("defined up to a height of 1.76 mm"), "{e}");
}

/// The Nikon 28-75 mm as the public transcription gives it: semi-apertures 29, 29, 26.2, 26.2, 20, 20, ...
fn nikon_as_transcribed() -> Lens {
    let mut lens = builtin_lens("nikon").unwrap();
    lens.surfaces[3].semi_aperture_mm = 26.2;
    lens.surfaces[4].semi_aperture_mm = 20.0;
    lens
}

#[test]
fn the_nikon_as_transcribed_loads_with_a_warning_and_a_lens_crossing_in_the_light_is_refused() {
    let text = flare_core::optics::formats::to_json(&nikon_as_transcribed());
    assert!(nikon_as_transcribed().validate().is_err(), "strict validation refuses the transcription");
    let loaded = read_lens_bytes(text.as_bytes(), Path::new("nikon.json")).unwrap();
    assert_eq!(loaded.warnings.len(), 1, "{:?}", loaded.warnings);
    let w = &loaded.warnings[0];
    assert!(
        w.starts_with(
            "surfaces 3 and 4 meet at a height of 18.61 mm, inside their clear semi-apertures (26.2 and 20 mm)"
        ) && w.contains("both clipped to 18.61 mm")
            && w.contains("deg off axis"),
        "{w}"
    );
    assert_eq!(w.matches("18.61").count(), 2, "each number once where it belongs: {w}");
    let lens = &loaded.lens;
    lens.validate().unwrap();
    for k in [3, 4] {
        assert!((lens.surfaces[k].semi_aperture_mm - 18.608).abs() < 1e-3, "{}", lens.surfaces[k].semi_aperture_mm);
    }
    // Only those two changed; the lens still forms its image (rays through the stop land).
    let builtin = builtin_lens("nikon").unwrap();
    for k in (0..lens.surfaces.len()).filter(|k| ![3, 4].contains(k)) {
        assert_eq!(lens.surfaces[k], builtin.surfaces[k]);
    }
    let fo = FirstOrder::d_line(lens).unwrap();
    let tracer = Tracer::new(lens, &LightPath::image(lens), D_LINE_NM, fo.sensor_z_mm());
    let on_axis = tracer.trace(
        &pupil_ray(&fo.entrance_pupil(), 0.0, 0.0, 0.9),
        TraceOptions { apply_apertures: true, ..Default::default() },
    );
    assert_eq!(on_axis.status, TraceStatus::Landed);

    // Closing the air gap to 0.01 mm makes them meet 2 mm from the axis, where on-axis light passes: refused.
    let mut crossing = nikon_as_transcribed();
    crossing.surfaces[3].thickness_mm = Some(0.01);
    let text = flare_core::optics::formats::to_json(&crossing);
    let e = read_lens_bytes(text.as_bytes(), Path::new("nikon.json")).unwrap_err().to_string();
    assert!(e.contains("surfaces 3 and 4 meet at a height of") && e.contains("on-axis light through the stop"), "{e}");
    assert_eq!(e.matches("meet at").count(), 1, "said once: {e}");
    assert!(!e.contains("99999") && !e.contains("00000"), "numbers rounded for people: {e}");
}

#[test]
fn the_aspheric_intersection_is_exact_and_reports_misses() {
    let mut s = Surface::new(20.0, Some(5.0), flare_core::optics::Medium::air(), 8.0);
    s.conic = -1.5;
    s.aspheric_r2 = 0.001;
    s.aspheric = vec![2e-5, -3e-8];
    let shape = s.shape();
    // Rays from in front of the vertex at several heights and slopes land on the surface itself.
    for (y, slope) in [(0.0, 0.0), (3.0, 0.05), (7.5, -0.2), (-6.0, 0.3)] {
        let d = DVec3::new(0.0, slope, 1.0).normalize();
        let p = DVec3::new(0.5, y, -4.0);
        let t = intersect_shape(p, d, &shape, 1.0).unwrap();
        let hit = p + t * d;
        let r = hit.x.hypot(hit.y);
        assert!((hit.z - s.sag_mm(r).unwrap()).abs() < 1e-12, "{y} {slope}: {hit}");
        let n = shape_normal(hit, &shape).unwrap();
        assert!((n.length() - 1.0).abs() < 1e-14 && n.z > 0.0);
    }
    // A ray parallel to the vertex plane and outside the surface's reach misses it, as an outcome.
    let mut sphere_cap = Surface::new(10.0, Some(5.0), flare_core::optics::Medium::air(), 8.0);
    sphere_cap.conic = 0.5;
    sphere_cap.aspheric = vec![1e-6];
    assert_eq!(intersect_shape(DVec3::new(0.0, 20.0, -1.0), DVec3::Y, &sphere_cap.shape(), 1.0), None);
}

#[test]
fn a_stop_in_glass_or_on_a_curved_surface_loads_and_forms_its_pupil() {
    // The dgauss's stop moved into the glass of the element behind it: a flat surface with glass on both
    // sides, which does not reflect, and still sets the entrance pupil.
    let mut lens = builtin_lens("dgauss").unwrap();
    let stop = lens.stop_index();
    let glass = lens.surfaces[stop + 1].medium.clone();
    lens.surfaces[stop - 1].medium = glass.clone();
    lens.surfaces[stop].medium = glass;
    lens.validate().unwrap();
    assert!(!lens.reflecting_surfaces().contains(&stop));
    let fo = FirstOrder::d_line(&lens).unwrap();
    assert!(fo.entrance_pupil_diameter_mm > 0.0 && fo.stop_surface == stop);
    // A curved stop on a lens surface reflects, and its ghosts cross the stop twice.
    let on_surface = flare_core::optics::library::with_stop_on_front_surface(&builtin_lens("heliar").unwrap()).unwrap();
    let s = on_surface.stop_index();
    assert!(!on_surface.surfaces[s].is_flat() && on_surface.reflecting_surfaces().contains(&s));
    let (i, j) = *on_surface.ghost_pairs().iter().find(|(i, j)| *i == s || *j == s).unwrap();
    assert_eq!(LightPath::ghost(&on_surface, i, j).unwrap().stop_crossings(&on_surface).len(), 2);
}

/// A FlareSim lens in the layout of its README's example: header, a comment row, a `stop` row, coatings.
const FLARESIM: &str = "name: Double Gauss 58mm f/2 (test)
focal_length: 58.0

surfaces:
# radius    thickness   ior     abbe    semi_ap  coating
  39.68     8.36        1.670   47.2    25.0     1
  152.73    0.20        1.000   0.0     25.0     0
  25.59     11.40       1.670   47.2    21.0     1
  0.0       2.50        1.699   30.1    21.0     0
  16.99     8.34        1.000   0.0     14.0     2
  stop      8.00        1.000   0.0     12.0     0
  -20.95    2.00        1.603   38.0    14.0     1
  0.0       9.53        1.658   57.3    16.0     0
  -26.86    0.20        1.000   0.0     16.0     1
  130.0     5.10        1.717   48.0    17.0     1
  -71.04    40.0        1.000   0.0     17.0     1
";

#[test]
fn flaresim_lens_files_read_by_extension_and_content() {
    let loaded = read_lens_bytes(FLARESIM.as_bytes(), Path::new("dg.lens")).unwrap();
    let lens = &loaded.lens;
    assert_eq!(lens.name, "Double Gauss 58mm f/2 (test)");
    assert_eq!(lens.surfaces.len(), 11);
    assert!(lens.surfaces[5].stop && lens.surfaces[5].is_flat());
    assert_eq!(lens.surfaces[0].medium.v_d, Some(47.2));
    assert!(matches!(lens.surfaces[0].coating, flare_core::optics::Coating::QuarterWave { .. }));
    assert_eq!(lens.surfaces[4].coating, flare_core::optics::Coating::broadband());
    assert!(loaded.warnings.iter().any(|w| w.contains("coating column")), "{:?}", loaded.warnings);
    // By content too (no extension), and the same lens.
    assert_eq!(read_lens(FLARESIM, None, "dg").unwrap().lens.surfaces, lens.surfaces);
    // The focal length it states is checked: a wrong one is said.
    let wrong = FLARESIM.replace("focal_length: 58.0", "focal_length: 85.0");
    let w = read_lens(&wrong, None, "dg").unwrap().warnings;
    assert!(w.iter().any(|w| w.contains("line 2: focal_length 85 mm")), "{w:?}");
    // Written back (our writer) and read again: the same optics.
    let text = flare_core::optics::formats::flaresim::write(&builtin_lens("dgauss").unwrap()).unwrap();
    let again = read_lens(&text, Some(LensFormat::FlareSimLens), "dg").unwrap().lens;
    let fo = |l: &Lens| FirstOrder::d_line(l).unwrap().efl_mm;
    assert!((fo(&again) - fo(&builtin_lens("dgauss").unwrap())).abs() < 1e-9);
    // Malformed rows name their line and the reason.
    for (edit, words) in [
        (FLARESIM.replace("152.73    0.20        1.000", "152.73"), vec!["line 7", "expected 6 columns", "found 4"]),
        (FLARESIM.replace("25.59", "25.5x"), vec!["line 8", "radius `25.5x`"]),
        (FLARESIM.replace("1.699   30.1", "1.699   abc"), vec!["line 9", "abbe `abc`"]),
        (FLARESIM.replace("surfaces:", "surfaces"), vec!["line 4", "neither a `key: value` header"]),
    ] {
        let e = read_lens(&edit, Some(LensFormat::FlareSimLens), "x").unwrap_err().to_string();
        for w in words {
            assert!(e.contains(w), "`{e}` lacks `{w}`");
        }
    }
}

/// An OpenLensFlare system in the layout of its examples: name, f-number, focal length, film, elements with
/// a coating, the stop and the sensor.
const OLF: &str = r#"<?xml version="1.0" encoding="UTF-8"?>
<opticalSystem>
    <name>triplet-test</name>
    <fnumber>4.0</fnumber>
    <effectiveFocalLength>50</effectiveFocalLength>
    <fieldOfView>40</fieldOfView>
    <filmWidth>36</filmWidth>
    <filmHeight>24</filmHeight>
    <elements>
        <element>
            <type>lensSpherical</type>
            <height>12.0</height>
            <thickness>4.0</thickness>
            <radius>30.0</radius>
            <refractiveIndex>1.62</refractiveIndex>
            <abbeNumber>60.3</abbeNumber>
            <coatingLambda>550</coatingLambda>
            <coatingIor>1.38</coatingIor>
        </element>
        <element>
            <type>lensSpherical</type>
            <height>12.0</height>
            <thickness>5.0</thickness>
            <radius>-200.0</radius>
            <refractiveIndex>1.0</refractiveIndex>
            <abbeNumber>89.3</abbeNumber>
            <coatingLambda>0</coatingLambda>
            <coatingIor>0</coatingIor>
        </element>
        <element>
            <type>apertureStop</type>
            <height>8.0</height>
            <thickness>4.0</thickness>
            <radius>0.0</radius>
            <refractiveIndex>1.0</refractiveIndex>
            <abbeNumber>89.3</abbeNumber>
            <coatingLambda>0</coatingLambda>
            <coatingIor>0</coatingIor>
        </element>
        <element>
            <type>lensSpherical</type>
            <height>9.0</height>
            <thickness>3.0</thickness>
            <radius>60.0</radius>
            <refractiveIndex>1.62</refractiveIndex>
            <abbeNumber>36.4</abbeNumber>
            <coatingLambda>0</coatingLambda>
            <coatingIor>0</coatingIor>
        </element>
        <element>
            <type>lensSpherical</type>
            <height>9.0</height>
            <thickness>40.0</thickness>
            <radius>-60.0</radius>
            <refractiveIndex>1.0</refractiveIndex>
            <abbeNumber>89.3</abbeNumber>
            <coatingLambda>0</coatingLambda>
            <coatingIor>0</coatingIor>
        </element>
        <element>
            <type>sensor</type>
            <height>43.0</height>
            <thickness>0.001</thickness>
            <radius>0.0</radius>
            <refractiveIndex>1.0</refractiveIndex>
            <abbeNumber>89.3</abbeNumber>
            <coatingLambda>0</coatingLambda>
            <coatingIor>0</coatingIor>
        </element>
    </elements>
</opticalSystem>
"#;

#[test]
fn openlensflare_systems_read_by_extension_and_content() {
    let loaded = read_lens_bytes(OLF.as_bytes(), Path::new("t.xml")).unwrap();
    let lens = &loaded.lens;
    assert_eq!(lens.name, "triplet-test");
    assert_eq!(lens.surfaces.len(), 5, "the sensor is not a surface");
    assert_eq!(lens.surfaces[0].semi_aperture_mm, 12.0, "<height> is the clear semi-aperture");
    assert_eq!(
        lens.surfaces[0].coating,
        flare_core::optics::Coating::QuarterWave { design_wavelength_nm: 550.0, layer_index: Some(1.38) }
    );
    assert!(lens.surfaces[2].stop);
    // <fnumber> sets the stop, and says so.
    let fo = FirstOrder::d_line(lens).unwrap();
    assert!((fo.f_number - 4.0).abs() < 1e-9, "{}", fo.f_number);
    assert!(
        loaded.warnings.iter().any(|w| w.starts_with("line 4: <fnumber> 4 sets the stop's")),
        "{:?}",
        loaded.warnings
    );
    assert_eq!(read_lens(OLF, None, "t").unwrap().lens.surfaces, lens.surfaces, "by content");
    for (edit, words) in [
        (
            OLF.replacen("<thickness>5.0</thickness>", "<thickness>5.0x</thickness>", 1),
            vec!["line 23", "<thickness> `5.0x`"],
        ),
        (OLF.replacen("lensSpherical", "lensAspherical", 1), vec!["line 11", "lensAspherical", "not supported"]),
        (OLF.replacen("</element>", "", 1), vec!["not well-formed XML"]),
        (OLF.replacen("<height>12.0</height>", "", 1), vec!["line 10", "no <height>"]),
        (OLF.replacen("<fnumber>4.0</fnumber>", "<fnumber>-1</fnumber>", 1), vec!["line 4", "<fnumber>"]),
    ] {
        let e = read_lens(&edit, Some(LensFormat::OpenLensFlareXml), "x").unwrap_err().to_string();
        for w in words {
            assert!(e.contains(w), "`{e}` lacks `{w}`");
        }
    }
}

/// "+" (`Lens::insert_dummy_after`, a surface with one medium on both sides) on every row of every shipped lens is optically inert: the lens stays
/// valid with the same focal length, ghost count and LUT fingerprint (`Lens::is_inert`) (and, but after the last row, the same back focal distance);
/// "x" (`Lens::remove_surface`) on the new row gives back exactly the lens (every field, so its EFL, BFD, ghosts
/// and vertices).
#[test]
fn a_dummy_surface_inserted_and_removed_on_every_row_of_every_shipped_lens_changes_nothing() {
    use flare_core::bake::lut_fingerprint;
    let config = flare_core::preset::Document::default().flare_config().unwrap();
    let mut rows = 0;
    for id in flare_core::optics::library::ids() {
        let lens = builtin_lens(id).unwrap();
        let before = FirstOrder::d_line(&lens).unwrap();
        let ghosts = lens.ghost_pairs().len();
        for k in 0..lens.surfaces.len() {
            let mut plus = lens.clone();
            let new = plus.insert_dummy_after(k).unwrap_or_else(|e| panic!("{id} row {k}: {e}"));
            assert_eq!(new, k + 1);
            plus.validate().unwrap_or_else(|e| panic!("{id} after + on row {k}: {e}"));
            let inserted = FirstOrder::d_line(&plus).unwrap();
            assert!(
                (inserted.efl_mm - before.efl_mm).abs() < 1e-9,
                "{id} row {k}: EFL {} -> {}",
                before.efl_mm,
                inserted.efl_mm
            );
            if k + 1 < lens.surfaces.len() {
                assert!((inserted.bfd_mm - before.bfd_mm).abs() < 1e-9, "{id} row {k}: BFD");
            }
            assert_eq!(plus.ghost_pairs().len(), ghosts, "{id} row {k}: a new reflecting surface");
            // Inert, so the LUT's fingerprint is the lens's: its LUT stays valid (and its cached LUT found).
            assert!(plus.is_inert(new), "{id} row {k}: the dummy is not inert");
            assert!(plus.without_inert().0.as_ref() == lens.without_inert().0.as_ref(), "{id} row {k}");
            assert_eq!(lut_fingerprint(&plus, &config), lut_fingerprint(&lens, &config), "{id} row {k}");
            plus.remove_surface(new).unwrap();
            let back = FirstOrder::d_line(&plus).unwrap();
            assert!(
                (back.efl_mm - before.efl_mm).abs() < 1e-9 && (back.bfd_mm - before.bfd_mm).abs() < 1e-9,
                "{id} row {k}"
            );
            assert_eq!(plus.ghost_pairs().len(), ghosts);
            for (a, b) in plus.vertex_z_mm().iter().zip(lens.vertex_z_mm()) {
                assert!((a - b).abs() < 1e-9, "{id} row {k}: a vertex moved");
            }
            assert_eq!(plus.surfaces.len(), lens.surfaces.len());
            assert!(plus == lens, "{id} row {k}: x gives back exactly the lens + was pressed on");
            rows += 1;
        }
    }
    eprintln!("{rows} rows of shipped lenses: + then x changes nothing");
    assert!(rows > 100);
}

/// A surface that could cut or bend light is never taken for inert (its LUT fingerprint is then its own): a
/// dummy made narrower than its neighbours, coated, made the stop, or given another medium.
#[test]
fn a_surface_that_could_cut_or_bend_light_is_not_inert() {
    use flare_core::bake::lut_fingerprint;
    use flare_core::optics::Coating;
    let config = flare_core::preset::Document::default().flare_config().unwrap();
    let lens = builtin_lens("pbrt_dgauss_50mm").unwrap();
    let mut plus = lens.clone();
    let k = plus.insert_dummy_after(1).unwrap();
    assert!(plus.is_inert(k));
    type Change = fn(&mut flare_core::optics::Surface);
    let changes: [(&str, Change); 4] = [
        ("narrower", |s| s.semi_aperture_mm *= 0.5),
        ("coated", |s| s.coating = Coating::QuarterWave { design_wavelength_nm: 550.0, layer_index: None }),
        ("stop", |s| s.stop = true),
        ("another medium", |s| s.medium.n_d += 0.01),
    ];
    for (what, change) in changes {
        let mut other = plus.clone();
        change(&mut other.surfaces[k]);
        assert!(!other.is_inert(k), "{what}");
        assert_ne!(lut_fingerprint(&other, &config), lut_fingerprint(&lens, &config), "{what}");
    }
}
