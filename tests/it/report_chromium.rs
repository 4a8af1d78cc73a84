//! The demo's report as a browser shows it: headless Chromium (Debian's `chromium`, installed
//! by `.ci/run`) loads the page and every figure must have drawn (pixels other than the white
//! background inside each chart's box, in a screenshot of the whole page), with no script
//! error. Skipped with a message where Chromium is absent, except under CI
//! (`RPKM_REQUIRE_PYTHON`, set by `.ci/run`).
//!
//! The README's picture of the report (`docs/report.png`, the first screen) is re-minted with
//! `RPKM_UPDATE_DOCS=1 cargo test --test it report_chromium`.
#![expect(
    clippy::cast_possible_truncation,
    clippy::cast_sign_loss,
    reason = "test and benchmark fixtures: counters, stamps and sizes far inside the target type's range"
)]

use std::path::{Path, PathBuf};
use std::process::Command;

fn chromium() -> Option<PathBuf> {
    let found = std::env::var_os("PATH").and_then(|paths| {
        std::env::split_paths(&paths)
            .flat_map(|d| ["chromium", "chromium-browser"].map(|n| d.join(n)))
            .find(|p| p.is_file())
    });
    if found.is_none() {
        assert!(
            std::env::var_os("RPKM_REQUIRE_PYTHON").is_none(),
            "RPKM_REQUIRE_PYTHON is set but chromium is not installed (apt-get install chromium)"
        );
        eprintln!("skipped: chromium is not installed (apt-get install chromium)");
    }
    found
}

/// Collects script errors from the start and, once the page has loaded, writes each chart's
/// box (page pixels) and the errors into the DOM as JSON.
const PROBE_HEAD: &str = "<script>window.__errors=[];\
addEventListener('error',e=>__errors.push(String(e.message||e)));\
addEventListener('unhandledrejection',e=>__errors.push(String(e.reason)));</script>";
const PROBE_BODY: &str = "<script>addEventListener('load',()=>{\
const boxes=[...document.querySelectorAll('figure.plot')].map(f=>{\
const s=f.querySelector('svg');const r=(s||f).getBoundingClientRect();\
return {svg:!!s,x:r.left+scrollX,y:r.top+scrollY,w:r.width,h:r.height,\
caption:(f.querySelector('figcaption')||{}).textContent||''}});\
const p=document.createElement('pre');p.id='rpkm-probe';\
p.textContent=JSON.stringify({errors:__errors,boxes,height:document.documentElement.scrollHeight});\
document.body.appendChild(p)});</script>";

struct Browser {
    exe: PathBuf,
    profile: tempfile::TempDir,
}

impl Browser {
    /// Chromium's output for `args` (own profile: tests run side by side).
    fn run(&self, args: &[String]) -> String {
        let out = Command::new(&self.exe)
            .args([
                "--headless",
                "--no-sandbox",
                "--disable-gpu",
                "--hide-scrollbars",
            ])
            .args(["--force-device-scale-factor=1", "--no-first-run"])
            .arg(format!("--user-data-dir={}", self.profile.path().display()))
            .args(args)
            .output()
            .expect("run chromium");
        assert!(
            out.status.success(),
            "chromium {args:?}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        String::from_utf8_lossy(&out.stdout).into_owned()
    }

    fn screenshot(&self, page: &Path, png: &Path, height: u32) {
        self.run(&[
            format!("--window-size=1280,{height}"),
            format!("--screenshot={}", png.display()),
            format!("file://{}", page.display()),
        ]);
    }
}

/// The probe's JSON out of the DOM Chromium printed (its text is HTML-escaped there).
fn probe(dom: &str) -> serde_json::Value {
    let start = dom.find("<pre id=\"rpkm-probe\">").expect("probe ran") + 21;
    let end = start + dom[start..].find("</pre>").expect("probe end");
    let text = dom[start..end]
        .replace("&lt;", "<")
        .replace("&gt;", ">")
        .replace("&quot;", "\"")
        .replace("&amp;", "&");
    serde_json::from_str(&text).expect("probe JSON")
}

/// RGB pixels of a PNG, with its width and height.
fn pixels(path: &Path) -> (Vec<u8>, usize, usize) {
    let file = std::fs::File::open(path).expect("screenshot");
    let mut reader = png::Decoder::new(std::io::BufReader::new(file))
        .read_info()
        .expect("png");
    let mut buf = vec![0; reader.output_buffer_size()];
    let info = reader.next_frame(&mut buf).expect("png frame");
    let channels = info.color_type.samples();
    assert!(channels >= 3, "{:?}", info.color_type);
    let rgb = buf[..info.buffer_size()]
        .chunks(channels)
        .flat_map(|p| [p[0], p[1], p[2]])
        .collect();
    (rgb, info.width as usize, info.height as usize)
}

/// Fraction of the box's pixels that are not (near) white.
fn drawn_fraction(rgb: &[u8], width: usize, height: usize, b: &serde_json::Value) -> f64 {
    let f = |k: &str| b[k].as_f64().expect(k).round() as usize;
    let (x0, y0) = (f("x"), f("y"));
    let (x1, y1) = ((x0 + f("w")).min(width), (y0 + f("h")).min(height));
    let (mut inked, mut all) = (0usize, 0usize);
    for y in y0..y1 {
        for x in x0..x1 {
            let p = &rgb[3 * (y * width + x)..3 * (y * width + x) + 3];
            all += 1;
            if p.iter().any(|c| *c < 235) {
                inked += 1;
            }
        }
    }
    inked as f64 / all.max(1) as f64
}

#[test]
fn every_figure_of_the_demo_report_draws_in_chromium() {
    let Some(exe) = chromium() else { return };
    let dir = tempfile::tempdir().expect("tempdir");
    let demo = dir.path().join("demo");
    let run = Command::new(env!("CARGO_BIN_EXE_rpkm"))
        .args(["demo", "--out"])
        .arg(&demo)
        .output()
        .expect("rpkm demo");
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let html = std::fs::read_to_string(demo.join("report.html")).expect("report");
    assert!(
        !html.contains("src=\"http") && !html.contains("href=\"http"),
        "network load"
    );
    let probed = dir.path().join("probed.html");
    let with_probe = html
        .replacen("<head>", &format!("<head>{PROBE_HEAD}"), 1)
        .replacen("</body>", &format!("{PROBE_BODY}</body>"), 1);
    std::fs::write(&probed, with_probe).expect("write probed page");
    let browser = Browser {
        exe,
        profile: tempfile::tempdir().expect("profile"),
    };
    let dom = browser.run(&[
        "--window-size=1280,1000".to_owned(),
        "--virtual-time-budget=5000".to_owned(),
        "--dump-dom".to_owned(),
        format!("file://{}", probed.display()),
    ]);
    let p = probe(&dom);
    assert_eq!(p["errors"], serde_json::json!([]), "script errors");
    let boxes = p["boxes"].as_array().expect("boxes");
    assert_eq!(boxes.len(), html.matches("<figure class=\"plot\"").count());
    assert!(boxes.len() >= 12, "{} figures", boxes.len());
    let height = p["height"].as_f64().expect("height").ceil() as u32;
    let shot = dir.path().join("page.png");
    browser.screenshot(&demo.join("report.html"), &shot, height);
    let (rgb, w, h) = pixels(&shot);
    assert_eq!((w, h), (1280, height as usize));
    for b in boxes {
        assert_eq!(b["svg"], true, "a figure without a chart: {b}");
        let inked = drawn_fraction(&rgb, w, h, b);
        assert!(inked > 0.02, "figure drew nothing ({inked:.4} inked): {b}");
    }
    let first = dir.path().join("first.png");
    browser.screenshot(&demo.join("report.html"), &first, 1000);
    if std::env::var_os("RPKM_UPDATE_DOCS").is_some() {
        let docs = Path::new(env!("CARGO_MANIFEST_DIR")).join("docs/report.png");
        std::fs::copy(&first, &docs).expect("docs/report.png");
    }
}
