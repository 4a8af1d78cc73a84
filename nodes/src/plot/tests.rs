//! Well-formedness and robustness of the charts.

use super::*;

/// Checks that `svg` is one well-formed `<svg>` element (balanced tags, no stray `<` or `&`
/// outside entities) and that every coordinate attribute is a finite number. Returns the
/// element names in document order.
fn check_svg(svg: &str) -> Vec<String> {
    assert!(svg.starts_with("<svg "), "{svg}");
    assert!(svg.trim_end().ends_with("</svg>"), "{svg}");
    let mut stack: Vec<String> = Vec::new();
    let mut names = Vec::new();
    let mut rest = svg;
    while let Some(open) = rest.find('<') {
        check_text(&rest[..open]);
        let close = rest[open..].find('>').expect("unclosed tag") + open;
        let tag = &rest[open + 1..close];
        rest = &rest[close + 1..];
        if let Some(name) = tag.strip_prefix('/') {
            let top = stack.pop().expect("closing tag without opening");
            assert_eq!(top, name.trim(), "mismatched closing tag");
            if stack.is_empty() {
                assert!(rest.trim().is_empty(), "content after the root element");
            }
            continue;
        }
        let self_closing = tag.ends_with('/');
        let tag = tag.trim_end_matches('/');
        let (name, attrs) = tag.split_once(' ').unwrap_or((tag, ""));
        assert!(
            !name.is_empty() && name.chars().all(|c| c.is_ascii_alphanumeric()),
            "bad tag name {name:?}"
        );
        assert!(
            !stack.is_empty() || names.is_empty(),
            "a second root element"
        );
        check_attributes(attrs);
        names.push(name.to_owned());
        if !self_closing {
            stack.push(name.to_owned());
        }
    }
    assert!(stack.is_empty(), "unclosed elements {stack:?}");
    names
}

fn check_text(text: &str) {
    let mut rest = text;
    while let Some(i) = rest.find('&') {
        let end = rest[i..].find(';').expect("unterminated entity") + i;
        let entity = &rest[i + 1..end];
        assert!(
            ["amp", "lt", "gt", "quot", "apos"].contains(&entity),
            "unknown entity {entity}"
        );
        rest = &rest[end + 1..];
    }
    assert!(!text.contains('>'), "stray > in {text:?}");
}

fn check_attributes(attrs: &str) {
    let mut rest = attrs.trim();
    while !rest.is_empty() {
        let eq = rest.find("=\"").expect("attribute without value");
        let key = rest[..eq].trim();
        let end = rest[eq + 2..].find('"').expect("unterminated attribute") + eq + 2;
        let value = &rest[eq + 2..end];
        check_text(value);
        assert!(!value.contains('<'), "< in attribute {key}");
        let numeric = [
            "x",
            "y",
            "x1",
            "y1",
            "x2",
            "y2",
            "cx",
            "cy",
            "r",
            "width",
            "height",
            "stroke-width",
            "dy",
            "font-size",
        ];
        if numeric.contains(&key) {
            let v: f64 = value.parse().unwrap_or_else(|_| panic!("{key}={value:?}"));
            assert!(v.is_finite(), "{key}={value}");
        }
        if key == "points" {
            for pair in value.split_whitespace() {
                for c in pair.split(',') {
                    let v: f64 = c.parse().unwrap_or_else(|_| panic!("points {value:?}"));
                    assert!(v.is_finite());
                }
            }
        }
        if key == "transform" || key == "viewBox" {
            assert!(!value.contains("NaN") && !value.contains("inf"), "{value}");
        }
        rest = rest[end + 1..].trim_start();
    }
}

fn count(svg: &str, needle: &str) -> usize {
    svg.matches(needle).count()
}

fn params() -> Vec<String> {
    ["l1", "l4", "l5", "xa1r", "xa4r", "gamma2", "d1 & <d2>"]
        .iter()
        .map(|s| s.to_string())
        .collect()
}

#[test]
fn bar_chart_has_one_bar_per_category_and_series() {
    let cats = params();
    let series = vec![
        (
            "dx \"x\"".to_owned(),
            vec![0.1, -0.2, f64::NAN, 1.0, 2.0, 0.0, 3.0],
        ),
        ("dy".to_owned(), vec![0.5, 0.25]),
        ("dψ".to_owned(), vec![f64::INFINITY; 9]),
    ];
    for log_y in [false, true] {
        let svg = bar_chart(
            "Sensitivity <model 29>",
            "µm / 0.1 mm",
            &cats,
            &series,
            &BarOptions { log_y },
        );
        check_svg(&svg);
        assert_eq!(count(&svg, r#"class="bar"#), cats.len() * series.len());
        assert!(svg.contains("d1 &amp; &lt;d2&gt;"));
        assert!(svg.contains("Sensitivity &lt;model 29&gt;"));
        assert!(svg.contains("dx &quot;x&quot;"));
        assert!(
            !svg.contains("NaN") || svg.contains("<title>"),
            "NaN only in tooltips"
        );
    }
}

#[test]
fn charts_survive_empty_and_non_finite_data() {
    let empty: Vec<String> = Vec::new();
    check_svg(&bar_chart("", "", &empty, &[], &BarOptions::default()));
    check_svg(&bar_chart(
        "t",
        "y",
        &params(),
        &[],
        &BarOptions { log_y: true },
    ));
    let nan_series = vec![("all nan".to_owned(), vec![f64::NAN; 7])];
    let svg = bar_chart(
        "t",
        "y",
        &params(),
        &nan_series,
        &BarOptions { log_y: true },
    );
    check_svg(&svg);
    assert_eq!(count(&svg, r#"class="bar"#), 7);

    let lines = vec![
        ("empty".to_owned(), vec![]),
        (
            "nan".to_owned(),
            vec![(f64::NAN, 1.0), (0.0, f64::INFINITY)],
        ),
        ("one".to_owned(), vec![(1.0, 1.0)]),
    ];
    for opts in [
        LineOptions::LINES,
        LineOptions::SCATTER,
        LineOptions::LINES_AND_MARKERS,
    ] {
        check_svg(&line_chart("t", "x", "y", &lines, &opts));
        check_svg(&line_chart("t", "x", "y", &[], &opts));
    }
    check_svg(&heat_map("t", &[], "µm"));
    check_svg(&heat_map(
        "t",
        &[(f64::NAN, 0.0, 1.0), (0.0, 0.0, f64::NAN)],
        "µm",
    ));
    check_svg(&heat_map("t", &[(0.0, 1700.0, 0.0)], "µm"));
    check_svg(&quiver("t", &[], "µm"));
    check_svg(&quiver(
        "t",
        &[(0.0, 0.0, f64::NAN, 1.0), (0.0, 0.0, 0.0, 0.0)],
        "µm",
    ));
    check_svg(&polar_deviation("t", &[], &[], 100.0));
    check_svg(&polar_deviation(
        "t",
        &[0.0, 1.0, f64::NAN],
        &[0.0, 0.0, 1.0],
        f64::NAN,
    ));
    check_svg(&polar_deviation("t", &[0.0, 1.0], &[5.0], 0.0));
}

#[test]
fn line_breaks_at_non_finite_points() {
    let series = vec![(
        "r".to_owned(),
        vec![
            (0.0, 0.0),
            (1.0, 1.0),
            (2.0, f64::NAN),
            (3.0, 1.0),
            (4.0, 2.0),
        ],
    )];
    let svg = line_chart("t", "t (s)", "r (µm)", &series, &LineOptions::LINES);
    check_svg(&svg);
    assert_eq!(count(&svg, "<polyline"), 2);
    let svg = line_chart("t", "t (s)", "r (µm)", &series, &LineOptions::SCATTER);
    assert_eq!(count(&svg, "<polyline"), 0);
    assert_eq!(
        count(&svg, "<circle"),
        4 + 1,
        "4 points and one legend marker"
    );
}

#[test]
fn heat_map_colours_are_centred_at_zero() {
    assert_eq!(field::diverging(0.0), "#f7f7f7");
    assert_eq!(field::diverging(-1.0), "#2166ac");
    assert_eq!(field::diverging(1.0), "#b2182b");
    assert_eq!(field::diverging(f64::NAN), "#f7f7f7");
    let pts: Vec<(f64, f64, f64)> = (0..11)
        .flat_map(|i| {
            (0..21).map(move |j| {
                (
                    -150.0 + 30.0 * i as f64,
                    700.0 + 100.0 * j as f64,
                    (i as f64 - 5.0) * 2.0,
                )
            })
        })
        .collect();
    let svg = heat_map("Residual", &pts, "Δx (µm)");
    check_svg(&svg);
    assert_eq!(count(&svg, r#"class="cell""#), 231);
}

#[test]
fn output_is_deterministic() {
    let pts = [(0.0, 700.0, 1.0, 2.0), (30.0, 800.0, -1.0, 0.5)];
    assert_eq!(quiver("q", &pts, "µm"), quiver("q", &pts, "µm"));
    let a: Vec<f64> = (0..37).map(|k| k as f64 * 0.17).collect();
    let d: Vec<f64> = a.iter().map(|x| (2.0 * x).sin()).collect();
    assert_eq!(
        polar_deviation("c", &a, &d, 100.0),
        polar_deviation("c", &a, &d, 100.0)
    );
}

#[test]
fn escape_covers_markup_and_control_characters() {
    assert_eq!(escape(r#"a<b>&"c"'"#), "a&lt;b&gt;&amp;&quot;c&quot;&apos;");
    assert_eq!(escape("x\u{1}y"), "x\u{FFFD}y");
}

/// Writes one example of each chart to `$TMPDIR/rpkm-plot-examples/` for a look in a browser:
/// `cargo test -p rpkm plot::tests::write_examples -- --ignored`.
#[test]
#[ignore = "writes files; run by hand to look at the charts"]
fn write_examples() {
    let dir = std::env::temp_dir().join("rpkm-plot-examples");
    std::fs::create_dir_all(&dir).expect("create the example folder");
    let names = [
        "l1", "l4", "l5", "xa1r", "xa4r", "xa5r", "ya1r", "ya4r", "ya5r", "xb1r", "xb4r", "xb5r",
        "yb1r", "yb4r", "yb5r", "d2", "gamma2", "l2", "l3", "xa2r", "xa3r", "ya2r", "ya3r", "xb2r",
        "xb3r", "yb2r", "yb3r", "d1", "gamma1",
    ];
    let cats: Vec<String> = names.iter().map(|s| s.to_string()).collect();
    let dx: Vec<f64> = (0..29).map(|k| ((k as f64) * 1.3).sin() * 0.1).collect();
    let dy: Vec<f64> = (0..29).map(|k| ((k as f64) * 0.7).cos() * 0.08).collect();
    let bars = bar_chart(
        "Sensitivity of the TCP to each parameter (model 29)",
        "max |ΔX| over the workspace (mm)",
        &cats,
        &[("Δx".to_owned(), dx), ("Δy".to_owned(), dy)],
        &BarOptions::default(),
    );
    let conds = bar_chart(
        "Condition number of the identification Jacobian",
        "condition number",
        &[
            "LT".into(),
            "KGM".into(),
            "DBB".into(),
            "LI".into(),
            "SELF".into(),
        ],
        &[
            (
                "model 24".to_owned(),
                vec![1.2e3, 85.0, 4.1e5, 2.2e2, 7.7e6],
            ),
            (
                "model 29".to_owned(),
                vec![3.4e3, 2.1e2, f64::NAN, 5.5e2, 1.1e8],
            ),
        ],
        &BarOptions { log_y: true },
    );
    let t: Vec<(f64, f64)> = (0..200)
        .map(|k| {
            (
                k as f64 * 18.0,
                ((k as f64) * 0.21).sin() * 4.0 + (k as f64) * 0.02,
            )
        })
        .collect();
    let t2: Vec<(f64, f64)> = t.iter().map(|&(x, y)| (x, -0.6 * y + 1.0)).collect();
    let scatter = line_chart(
        "Residuals against time",
        "t (s)",
        "residual (µm)",
        &[("x".to_owned(), t), ("y".to_owned(), t2)],
        &LineOptions::SCATTER,
    );
    let grid: Vec<(f64, f64)> = (0..11)
        .flat_map(|i| (0..21).map(move |j| (-150.0 + 30.0 * i as f64, 700.0 + 100.0 * j as f64)))
        .collect();
    let heat: Vec<(f64, f64, f64)> = grid
        .iter()
        .map(|&(x, y)| {
            (
                x,
                y,
                x / 150.0 * 20.0 + ((y - 1700.0) / 1000.0).powi(2) * 15.0 - 5.0,
            )
        })
        .collect();
    let heat = heat_map("Residual Δx over the workspace", &heat, "Δx (µm)");
    let arrows: Vec<(f64, f64, f64, f64)> = grid
        .iter()
        .map(|&(x, y)| (x, y, x / 150.0 * 10.0, (y - 1700.0) / 1000.0 * 8.0))
        .collect();
    let arrows = quiver("Residual vectors", &arrows, "µm");
    let a: Vec<f64> = (0..37)
        .map(|k| k as f64 * std::f64::consts::TAU / 36.0)
        .collect();
    let d: Vec<f64> = a
        .iter()
        .map(|&x| 8.0 + 20.0 * (2.0 * x).cos() + 5.0 * (3.0 * x).sin())
        .collect();
    let polar = polar_deviation("Circular test, radius 100 mm (KGM29)", &a, &d, 100.0);
    for (name, svg) in [
        ("bars", bars),
        ("conditions", conds),
        ("scatter", scatter),
        ("heat", heat),
        ("quiver", arrows),
        ("polar", polar),
    ] {
        check_svg(&svg);
        std::fs::write(dir.join(format!("{name}.svg")), svg).expect("write an example");
    }
}
