//! The machine drawn from rpkm-core's geometry: both guides, the carriers, the five rods and
//! the platform at a pose (inverse model), in the machine frame (mm). Nothing is placed by
//! hand: every point comes from `geometry::{igm, carrier_joint, platform_joint, guide_frame}`.

use super::{escape, Frame};
use nalgebra::Vector2;
use rpkm_core::geometry::{self, GeometryError};
use rpkm_core::params::{Guide, Model, Params, RODS};
use std::fmt::Write as _;

/// The machine at one pose.
#[derive(Clone, Debug)]
pub struct Machine {
    /// Each guide from its lowest to its highest drawn point.
    pub guides: [(Vector2<f64>, Vector2<f64>); 2],
    /// Per rod (1..=5): platform joint A, carrier joint B.
    pub rods: [(Vector2<f64>, Vector2<f64>); 5],
    /// Platform outline through its joints, and the TCP.
    pub platform: Vec<Vector2<f64>>,
    pub tcp: Vector2<f64>,
    /// Actuator positions of the pose.
    pub q: [f64; 4],
}

impl Machine {
    /// The machine `p` with its TCP at (x, y); the guides drawn over the actuator travel
    /// `travel` (lowest and highest q of the campaign, mm).
    pub fn at(p: &Params, x: f64, y: f64, travel: (f64, f64)) -> Result<Machine, GeometryError> {
        let sol = geometry::igm(p, Model::M29, x, y)?;
        let q = sol.q();
        let psi = sol.psi();
        let rods = RODS.map(|r| {
            (
                geometry::platform_joint(p, &r, x, y, psi),
                geometry::carrier_joint(p, &r, q[r.actuator]),
            )
        });
        let guide = |g: Guide| {
            let (o, e, _) = geometry::guide_frame(p, g);
            (o + e * (travel.0 - 250.0), o + e * (travel.1 + 650.0))
        };
        // joints of rods 1, 2, 3, 4 are the platform's corners (rod 5's joint sits on rod 1's)
        let platform = [0, 1, 2, 3].map(|i| rods[i].0).to_vec();
        Ok(Machine {
            guides: [guide(Guide::G1), guide(Guide::G2)],
            rods,
            platform,
            tcp: Vector2::new(x, y),
            q,
        })
    }

    /// The bounding box of the drawing (mm): (x range, y range).
    pub fn extent(&self) -> ((f64, f64), (f64, f64)) {
        let pts = self
            .guides
            .iter()
            .flat_map(|g| [g.0, g.1])
            .chain(self.rods.iter().flat_map(|r| [r.0, r.1]));
        let (mut x, mut y) = (
            (f64::INFINITY, f64::NEG_INFINITY),
            (f64::INFINITY, f64::NEG_INFINITY),
        );
        for p in pts {
            x = (x.0.min(p.x), x.1.max(p.x));
            y = (y.0.min(p.y), y.1.max(p.y));
        }
        (x, y)
    }

    /// The machine as a thumbnail `width` px wide at true scale, thin lines, with the
    /// rectangle `view` (mm) in red: where a map of the workspace lies in the machine.
    pub fn thumbnail(&self, width: f64, view: ((f64, f64), (f64, f64))) -> String {
        let ((x0, x1), (y0, y1)) = self.extent();
        let height = width * (y1 - y0) / (x1 - x0);
        let f = Frame {
            x: (x0, x1),
            y: (y0, y1),
            px: (2.0, width - 2.0),
            py: (height - 2.0, 2.0),
        };
        let line = |a: Vector2<f64>, b: Vector2<f64>, colour: &str, w: f64| {
            let (pa, pb) = (f.at(a.x, a.y), f.at(b.x, b.y));
            format!(
                "<line x1=\"{:.1}\" y1=\"{:.1}\" x2=\"{:.1}\" y2=\"{:.1}\" stroke=\"{colour}\" stroke-width=\"{w}\"/>",
                pa.0, pa.1, pb.0, pb.1
            )
        };
        let mut o = format!(
            "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{width:.0}\" height=\"{height:.0}\" viewBox=\"0 0 {width:.0} {height:.0}\"><title>the machine at true scale; red: the map's view</title>"
        );
        for g in &self.guides {
            o.push_str(&line(g.0, g.1, "#9aa0a6", 2.5));
        }
        for r in &self.rods {
            o.push_str(&line(r.0, r.1, "#2f3b47", 1.0));
        }
        for (k, a) in self.platform.iter().enumerate() {
            let b = self.platform[(k + 1) % self.platform.len()];
            o.push_str(&line(*a, b, "#51606f", 1.2));
        }
        let (a, b) = (f.at(view.0 .0, view.1 .1), f.at(view.0 .1, view.1 .0));
        let _ = write!(
            o,
            "<rect x=\"{:.1}\" y=\"{:.1}\" width=\"{:.1}\" height=\"{:.1}\" fill=\"#b2182b\" fill-opacity=\"0.15\" stroke=\"#b2182b\" stroke-width=\"1.2\"/></svg>",
            a.0,
            a.1,
            (b.0 - a.0).max(1.0),
            (b.1 - a.1).max(1.0)
        );
        o
    }

    /// SVG of the machine in `f`'s pixels: guides grey, carriers as blocks on them, rods dark,
    /// the platform light steel with its TCP; each part names itself on hover.
    pub fn svg(&self, f: &Frame) -> String {
        let mut o = String::from("<g class=\"machine\" stroke-linecap=\"round\">");
        for (k, (a, b)) in self.guides.iter().enumerate() {
            let (pa, pb) = (f.at(a.x, a.y), f.at(b.x, b.y));
            let _ = write!(
                o,
                "<line x1=\"{:.1}\" y1=\"{:.1}\" x2=\"{:.1}\" y2=\"{:.1}\" stroke=\"#9aa0a6\" stroke-width=\"7\"><title>guide {}</title></line>",
                pa.0, pa.1, pb.0, pb.1, k + 1
            );
        }
        let pts: Vec<String> = self
            .platform
            .iter()
            .map(|p| {
                let (x, y) = f.at(p.x, p.y);
                format!("{x:.1},{y:.1}")
            })
            .collect();
        let _ = write!(
            o,
            "<polygon points=\"{}\" fill=\"#c9d6e3\" fill-opacity=\"0.55\" stroke=\"#51606f\" stroke-width=\"1.5\"><title>platform, TCP at x {:.0}, y {:.0} mm</title></polygon>",
            pts.join(" "),
            self.tcp.x,
            self.tcp.y
        );
        for (i, (a, b)) in self.rods.iter().enumerate() {
            let (pa, pb) = (f.at(a.x, a.y), f.at(b.x, b.y));
            let r = &RODS[i];
            let _ = write!(
                o,
                "<line x1=\"{:.1}\" y1=\"{:.1}\" x2=\"{:.1}\" y2=\"{:.1}\" stroke=\"#2f3b47\" stroke-width=\"2\"><title>rod {} on carrier {} (q{} = {:.1} mm)</title></line>\
                 <rect x=\"{:.1}\" y=\"{:.1}\" width=\"10\" height=\"10\" fill=\"#51606f\"><title>carrier {}</title></rect>\
                 <circle cx=\"{:.1}\" cy=\"{:.1}\" r=\"2.5\" fill=\"#2f3b47\"/>",
                pa.0,
                pa.1,
                pb.0,
                pb.1,
                r.number,
                r.actuator + 1,
                r.actuator + 1,
                self.q[r.actuator],
                pb.0 - 5.0,
                pb.1 - 5.0,
                r.actuator + 1,
                pa.0,
                pa.1
            );
        }
        let (tx, ty) = f.at(self.tcp.x, self.tcp.y);
        let _ = write!(
            o,
            "<path d=\"M{:.1},{ty:.1}h12M{tx:.1},{:.1}v12\" stroke=\"#b2182b\" stroke-width=\"2\"><title>{}</title></path></g>",
            tx - 6.0,
            ty - 6.0,
            escape("TCP")
        );
        o
    }
}
