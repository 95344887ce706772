//! Zemax AGF glass catalogues: the format every glass vendor publishes (SCHOTT, OHARA, HOYA, CDGM, ...).
//!
//! # How it works
//! An AGF file is a list of records, one per glass, each opened by an `NM` line:
//! `NM name formula MIL n_d V_d exclude status [melt frequency]`, followed by `CD c1 .. c10` (the dispersion
//! formula's coefficients, wavelengths in micrometres) and `LD min max` (the valid wavelength range, um).
//! Every other line (`CC` comments, `GC`, `ED` thermal data, `TD`, `OD`, `IT` transmission) does not change a
//! flare and is skipped. [`parse_agf`] reads a catalogue into [`CatalogueGlass`]es; a malformed `NM` or
//! `CD` line, a `CD` before any `NM`, an unknown formula or a glass without coefficients is refused with the
//! line and the reason, and nothing of the file is kept. The formulas (L = wavelength in um):
//! 1. Schott: `n^2 = a0 + a1 L^2 + a2 L^-2 + a3 L^-4 + a4 L^-6 + a5 L^-8`
//! 2. Sellmeier 1: `n^2 - 1 = K1 L^2/(L^2 - L1) + K2 L^2/(L^2 - L2) + K3 L^2/(L^2 - L3)` (CD: K1 L1 K2 L2 K3 L3)
//! 3. Herzberger: `n = A + B M + C M^2 + D L^2 + E L^4 + F L^6`, `M = 1/(L^2 - 0.028)`
//! 4. Sellmeier 2: `n^2 = 1 + A + B1 L^2/(L^2 - l1^2) + B2/(L^2 - l2^2)` (CD: A B1 l1 B2 l2)
//! 5. Conrady: `n = n0 + A/L + B/L^3.5`
//! 6. Sellmeier 3: four Sellmeier 1 terms (CD: K1 L1 .. K4 L4)
//! 7. Handbook of Optics 1: `n^2 = A + B/(L^2 - C) - D L^2`
//! 8. Handbook of Optics 2: `n^2 = A + B L^2/(L^2 - C) - D L^2`
//! 9. Sellmeier 4: `n^2 = A + B L^2/(L^2 - C) + D L^2/(L^2 - E)`
//! 10. Extended: `n^2 = a0 + a1 L^2 + a2 L^-2 + a3 L^-4 + a4 L^-6 + a5 L^-8 + a6 L^-10 + a7 L^-12`
//! 11. Sellmeier 5: five Sellmeier 1 terms (CD: K1 L1 .. K5 L5)
//! 12. Extended 2: `n^2 = a0 + a1 L^2 + a2 L^-2 + a3 L^-4 + a4 L^-6 + a5 L^-8 + a6 L^4 + a7 L^6`
//! 13. Extended 3: `n^2 = a0 + a1 L^2 + a2 L^4 + a3 L^-2 + a4 L^-4 + a5 L^-6 + a6 L^-8 + a7 L^-10 + a8 L^-12`
//!
//! Where a formula's value is not a real index (a pole, a negative n^2) [`CatalogueGlass::formula_index`]
//! returns `None`; the dispersion model then falls back to the glass's n_d and V_d (see [`super::glass`]).

/// One catalogue glass: its catalogue (vendor), name, AGF dispersion formula and coefficients (wavelength in
/// micrometres), and the published n_d and V_d.
#[derive(Clone, Debug, PartialEq)]
pub struct CatalogueGlass {
    pub name: String,
    pub catalogue: String,
    pub formula: u8,
    pub coefficients: [f64; 10],
    pub n_d: f64,
    pub v_d: f64,
    /// The range the formula is valid over (um), when the catalogue says.
    pub range_um: Option<[f64; 2]>,
}

impl CatalogueGlass {
    /// The catalogue formula's own index at `wavelength_nm` (not shifted to a file's n_d); `None` where the
    /// formula gives no real index.
    pub fn formula_index(&self, wavelength_nm: f64) -> Option<f64> {
        formula_index(self.formula, &self.coefficients, wavelength_nm * 1e-3)
    }
}

/// Why an AGF file could not be read: the line and the reason.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("AGF {catalogue} line {line}: {message}")]
pub struct AgfError {
    pub catalogue: String,
    pub line: usize,
    pub message: String,
}

/// Highest formula number the reader knows.
pub(crate) const MAX_FORMULA: u8 = 13;

/// Reads an AGF text as catalogue `catalogue` (the vendor's name, by convention the file stem).
pub fn parse_agf(text: &str, catalogue: &str) -> Result<Vec<CatalogueGlass>, AgfError> {
    let error = |line: usize, message: String| AgfError {
        catalogue: catalogue.to_owned(),
        line,
        message: crate::files::clean(&message),
    };
    let mut glasses: Vec<(usize, CatalogueGlass, bool)> = Vec::new();
    for (index, raw) in text.lines().enumerate() {
        let line = index + 1;
        let tokens: Vec<&str> = raw.split_whitespace().collect();
        let Some(&keyword) = tokens.first() else { continue };
        match keyword {
            "NM" => {
                if tokens.len() < 6 {
                    return Err(error(
                        line,
                        format!("NM has {} fields; it needs name, formula, MIL, n_d, V_d", tokens.len() - 1),
                    ));
                }
                let number = |k: usize, what: &str| -> Result<f64, AgfError> {
                    tokens[k]
                        .parse::<f64>()
                        .ok()
                        .filter(|v| v.is_finite())
                        .ok_or_else(|| error(line, format!("NM {what} `{}` is not a number", tokens[k])))
                };
                let formula = number(2, "formula")?;
                if formula.fract() != 0.0 || !(1.0..=f64::from(MAX_FORMULA)).contains(&formula) {
                    return Err(error(
                        line,
                        format!("formula {formula} of {} is not one of 1 to {MAX_FORMULA}", tokens[1]),
                    ));
                }
                let (n_d, v_d) = (number(4, "n_d")?, number(5, "V_d")?);
                if !(1.0..=4.0).contains(&n_d) {
                    return Err(error(line, format!("n_d {n_d} of {} is not an optical glass's", tokens[1])));
                }
                let glass = CatalogueGlass {
                    name: tokens[1].to_owned(),
                    catalogue: catalogue.to_owned(),
                    formula: formula as u8,
                    coefficients: [0.0; 10],
                    n_d,
                    v_d,
                    range_um: None,
                };
                glasses.push((line, glass, false));
            }
            "CD" => {
                let Some((_, glass, seen)) = glasses.last_mut() else {
                    return Err(error(line, "CD before any NM line (no glass to give coefficients to)".to_owned()));
                };
                for (k, t) in tokens[1..].iter().enumerate().take(10) {
                    glass.coefficients[k] = t
                        .parse::<f64>()
                        .ok()
                        .filter(|v| v.is_finite())
                        .ok_or_else(|| error(line, format!("CD coefficient {} `{t}` is not a number", k + 1)))?;
                }
                *seen = true;
            }
            "LD" => {
                if let Some((_, glass, _)) = glasses.last_mut() {
                    let v: Vec<f64> = tokens[1..].iter().filter_map(|t| t.parse().ok()).collect();
                    if v.len() < 2 || !(v[0].is_finite() && v[1].is_finite() && v[0] < v[1]) {
                        return Err(error(line, "LD needs the valid range as two increasing numbers (um)".to_owned()));
                    }
                    glass.range_um = Some([v[0], v[1]]);
                }
            }
            _ => {}
        }
    }
    if let Some((line, glass, _)) = glasses.iter().find(|(_, _, seen)| !seen) {
        return Err(error(*line, format!("glass {} has no CD line (no dispersion coefficients)", glass.name)));
    }
    if glasses.is_empty() {
        return Err(error(0, "no NM line: not an AGF glass catalogue".to_owned()));
    }
    Ok(glasses.into_iter().map(|(_, g, _)| g).collect())
}

/// The index by AGF formula `formula` with coefficients `c` at `wavelength_um`; `None` where it is not a
/// real index.
pub(crate) fn formula_index(formula: u8, c: &[f64; 10], wavelength_um: f64) -> Option<f64> {
    let l = wavelength_um;
    let l2 = l * l;
    let sellmeier =
        |pairs: usize| -> f64 { 1.0 + (0..pairs).map(|k| c[2 * k] * l2 / (l2 - c[2 * k + 1])).sum::<f64>() };
    let n2 = match formula {
        1 => c[0] + c[1] * l2 + c[2] / l2 + c[3] / l2.powi(2) + c[4] / l2.powi(3) + c[5] / l2.powi(4),
        2 => sellmeier(3),
        3 => {
            let m = 1.0 / (l2 - 0.028);
            let n = c[0] + c[1] * m + c[2] * m * m + c[3] * l2 + c[4] * l2.powi(2) + c[5] * l2.powi(3);
            return (n.is_finite() && n >= 1.0).then_some(n);
        }
        4 => 1.0 + c[0] + c[1] * l2 / (l2 - c[2] * c[2]) + c[3] / (l2 - c[4] * c[4]),
        5 => {
            let n = c[0] + c[1] / l + c[2] / l.powf(3.5);
            return (n.is_finite() && n >= 1.0).then_some(n);
        }
        6 => sellmeier(4),
        7 => c[0] + c[1] / (l2 - c[2]) - c[3] * l2,
        8 => c[0] + c[1] * l2 / (l2 - c[2]) - c[3] * l2,
        9 => c[0] + c[1] * l2 / (l2 - c[2]) + c[3] * l2 / (l2 - c[4]),
        10 => (0..6).fold(c[0] + c[1] * l2, |acc, k| acc + c[k + 2] / l2.powi(k as i32 + 1)),
        11 => sellmeier(5),
        12 => {
            c[0] + c[1] * l2
                + c[2] / l2
                + c[3] / l2.powi(2)
                + c[4] / l2.powi(3)
                + c[5] / l2.powi(4)
                + c[6] * l2.powi(2)
                + c[7] * l2.powi(3)
        }
        13 => c[0] + c[1] * l2 + c[2] * l2.powi(2) + (0..6).map(|k| c[k + 3] / l2.powi(k as i32 + 1)).sum::<f64>(),
        _ => return None,
    };
    (n2.is_finite() && n2 >= 1.0).then(|| n2.sqrt())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_broken_line_is_refused_with_its_number() {
        let good = "CC test\nNM G1 2 517642 1.5168 64.17 0 1\nCD 1.03961212 0.00600069867 0.231792344 0.0200179144 1.01046945 103.560653\nLD 0.3 2.5\n";
        assert_eq!(parse_agf(good, "T").unwrap().len(), 1);
        for (text, words) in [
            ("NM G1 2 517642 1.5168\n", vec!["line 1", "NM has 4 fields"]),
            ("NM G1 x 517642 1.5168 64.17 0 1\nCD 1\n", vec!["line 1", "formula `x`"]),
            ("NM G1 42 517642 1.5168 64.17 0 1\nCD 1\n", vec!["line 1", "formula 42"]),
            ("CC\nCD 1 2 3\n", vec!["line 2", "CD before any NM"]),
            ("NM G1 2 517642 1.5168 64.17 0 1\nCD 1.0 0.006 zz\n", vec!["line 2", "coefficient 3 `zz`"]),
            (
                "NM G1 2 517642 1.5168 64.17 0 1\nLD 0.3 2.5\nNM G2 2 1 1.6 40 0 1\nCD 1\n",
                vec!["line 1", "G1 has no CD"],
            ),
            ("NM G1 2 517642 0.5 64.17 0 1\nCD 1\n", vec!["line 1", "n_d 0.5"]),
            ("NM G1 2 517642 1.5 64.17 0 1\nCD 1\nLD 2.5 0.3\n", vec!["line 3", "LD"]),
            ("just text\n", vec!["no NM line"]),
        ] {
            let e = parse_agf(text, "T").unwrap_err().to_string();
            for w in words {
                assert!(e.contains(w), "`{e}` lacks `{w}` for {text:?}");
            }
        }
    }

    /// Formula 1 (Schott) against a vendor's own data: the first nine glasses of CDGM's Zemax catalogue (as
    /// distributed with Zemax; NM and CD lines verbatim). Their fits give the published n_d to 1e-5; their
    /// V_d only to 0.1, the fit's residual in n_F - n_C (SCHOTT's Sellmeier fits do it to 0.005).
    #[test]
    fn the_schott_formula_reproduces_cdgm_glasses() {
        let text = "CC Zemax AGF file (www.radiantzemax.com)
NM H-QK1 1 470668 1.470470 66.83 0
CD 2.138771500E+000 -9.647612200E-003 8.696348700E-003 2.287728600E-004 -1.368426300E-005 7.599432300E-007 0 0
NM H-QK3 1 487700 1.487460 70.04 0
CD 2.188902400E+000 -9.626529700E-003 8.808112200E-003 1.948691800E-004 -9.343856700E-006 5.391792900E-007 0 0
NM H-QK3L 1 487704 1.487490 70.44 0
CD 2.189743800E+000 -1.005912300E-002 8.387712600E-003 3.042571500E-004 -2.364083000E-005 1.114913000E-006 0 0
NM K4A 1 508611 1.508020 61.05 0
CD 2.232789900E+000 -2.393578300E-003 1.755166100E-002 -1.596414000E-003 2.248271800E-004 -1.064892400E-005 0 0
NM H-K5 1 510634 1.510070 63.36 0
CD 2.250183560E+000 -8.940661560E-003 1.143178290E-002 -7.333932780E-005 3.496166950E-005 -1.801007750E-006 0 0
NM H-K6 1 511605 1.511120 60.46 0
CD 2.250953100E+000 -7.976942900E-003 1.217291700E-002 -9.999791600E-005 4.177616400E-005 -2.091262300E-006 0 0
NM H-K7 1 515606 1.514780 60.63 0
CD 2.264180300E+000 -9.566170900E-003 1.065646900E-002 4.303269800E-004 -4.054725600E-005 2.530155900E-006 0 0
NM H-K9L 1 517642 1.516800 64.20 0
CD 2.269151100E+000 -8.515862900E-003 1.227044500E-002 -2.516883500E-004 4.898982100E-005 -2.067266500E-006 0 0
NM H-K10 1 518590 1.518180 58.95 0
CD 2.272712800E+000 -9.503807000E-003 1.154474500E-002 2.643155300E-004 -1.265556300E-005 1.088076200E-006 0 0
";
        let glasses = parse_agf(text, "CDGM").unwrap();
        assert_eq!(glasses.len(), 9);
        for g in &glasses {
            let n = |nm: f64| g.formula_index(nm).unwrap();
            let (d, v) = (n(587.5618), (n(587.5618) - 1.0) / (n(486.1327) - n(656.2725)));
            assert!((d - g.n_d).abs() < 1e-5, "{}: n_d {d} vs {}", g.name, g.n_d);
            assert!((v - g.v_d).abs() < 0.1, "{}: V_d {v} vs {}", g.name, g.v_d);
        }
    }

    #[test]
    fn the_schott_formula_and_sellmeier_agree_where_they_should() {
        // Formula 1 with a0 = 1 + sum K and only the first Laurent terms is close to Sellmeier for a weak
        // glass; here just check a known identity: Sellmeier 3 (formula 6) with a zero fourth term equals
        // Sellmeier 1 (formula 2), and Sellmeier 5 (11) likewise.
        let c = [1.03961212, 0.00600069867, 0.231792344, 0.0200179144, 1.01046945, 103.560653, 0.0, 0.0, 0.0, 0.0];
        let n2 = formula_index(2, &c, 0.5875618).unwrap();
        assert!((n2 - 1.5168).abs() < 1e-5, "{n2}");
        assert_eq!(formula_index(6, &c, 0.5875618), Some(n2));
        assert_eq!(formula_index(11, &c, 0.5875618), Some(n2));
        assert_eq!(formula_index(2, &c, (0.00600069867f64).sqrt()), None, "at a pole there is no index");
        assert_eq!(formula_index(14, &c, 0.5), None);
    }
}
