//! `~/load_calibration` and `~/save_calibration` (`rpkm_msgs/srv/LoadCalibration`,
//! `SaveCalibration`: a calibration JSON path) of the nodes that hold a geometry: the
//! estimator, the preload monitor and the calibrator. A cell controller loads a calibration
//! into a running node, or saves the one it holds, without a restart. On DDS only (the
//! services of ROS 2); answered between samples, from the node's loop.
//!
//! ```text
//! ros2 service call /rpkm/tcp_estimator/load_calibration rpkm_msgs/srv/LoadCalibration \
//!   "{path: /cell/cal.json}"
//! ```

use crate::calibration_file::CalibrationFile;
use std::path::Path;

use rpkm_core::params::{Model, NAMES};
use rpkm_msgs::calibration_srv::{
    CalibrationFileRequest as Request, CalibrationFileResponse as Response, LOAD_CALIBRATION,
    SAVE_CALIBRATION,
};
use rpkm_transport::dds_calls::{CallServer, ServiceType};

use super::context::NodeContext;
use super::geometry::Geometry;

/// The two services of one node.
pub struct CalibrationServices {
    load: CallServer<Request, Response>,
    save: CallServer<Request, Response>,
}

impl CalibrationServices {
    /// The services of `ctx`'s node, when it is on DDS (`None` on iceoryx2 only).
    pub fn open(ctx: &NodeContext) -> anyhow::Result<Option<Self>> {
        let Some(dds) = ctx.transport.dds_node() else {
            return Ok(None);
        };
        let kind = |name| ServiceType {
            package: rpkm_msgs::PACKAGE,
            name,
        };
        Ok(Some(Self {
            load: dds.serve_calls("load_calibration", kind(LOAD_CALIBRATION))?,
            save: dds.serve_calls("save_calibration", kind(SAVE_CALIBRATION))?,
        }))
    }

    /// Answers the requests waiting: a save writes `current`; a load returns the geometry
    /// it read (the last one, when several came), which the node then takes.
    pub fn poll(&self, ctx: &NodeContext, current: &Geometry) -> Option<Geometry> {
        while let Some(call) = self.save.try_next() {
            let response = match save(current, Path::new(&call.request.path)) {
                Ok(what) => answer(ctx, true, what),
                Err(e) => answer(ctx, false, format!("WARN: save_calibration: {e:#}")),
            };
            call.answer(response);
        }
        let mut loaded = None;
        while let Some(call) = self.load.try_next() {
            let response = match load(current, Path::new(&call.request.path)) {
                Ok(g) => {
                    let what = format!(
                        "loaded the geometry of {} (model {}): the next sample uses it",
                        g.source,
                        g.model.number()
                    );
                    loaded = Some(g);
                    answer(ctx, true, what)
                }
                Err(e) => answer(ctx, false, format!("WARN: load_calibration: {e:#}")),
            };
            call.answer(response);
        }
        loaded
    }
}

/// Logs `message` and makes it the reply.
fn answer(ctx: &NodeContext, success: bool, message: String) -> Response {
    ctx.log(&message);
    Response { success, message }
}

/// The geometry of `current` with the parameters and the effects of the calibration JSON at
/// `path` (the node's model, stiffness and effects file stay).
fn load(current: &Geometry, path: &Path) -> anyhow::Result<Geometry> {
    let doc = CalibrationFile::read(path)?;
    let mut params = crate::input::params_of(path, &doc)?;
    if current.model == Model::M24 {
        params = params.with_perfect_parallelogram();
    }
    let effects = current.effects.read_calibration(path, &doc)?;
    Ok(Geometry {
        params,
        model: current.model,
        stiffness: current.stiffness,
        source: format!("{}{}", path.display(), effects.describe()),
        effects,
    })
}

/// Writes `g` as calibration JSON (`model`, `parameters` in mm and rad, `source`, and the
/// applied effects' `effects` and `effects_file` as `rpkm calibrate --json` writes them), the
/// file [`load`] and `geometry_file` read.
fn save(g: &Geometry, path: &Path) -> anyhow::Result<String> {
    let mut doc = CalibrationFile {
        parameters: NAMES
            .iter()
            .enumerate()
            .map(|(i, name)| ((*name).to_owned(), g.params[i]))
            .collect(),
        ..CalibrationFile::default()
    };
    doc.report.insert("model".into(), g.model.number().into());
    doc.report.insert("source".into(), g.source.clone().into());
    if let Some((effects, file)) = g.effects.to_json() {
        doc.effects = serde_json::from_value(effects)?;
        doc.effects_file = Some(serde_json::from_value(file)?);
    }
    let doc = doc.to_value()?;
    let text = serde_json::to_string_pretty(&doc)?;
    std::fs::write(path, text + "\n")
        .map_err(|e| anyhow::anyhow!("{}: cannot write: {e}", path.display()))?;
    Ok(format!(
        "saved the geometry of {} (model {}) to {}",
        g.source,
        g.model.number(),
        path.display()
    ))
}
