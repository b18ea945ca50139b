//! glTF 2.0 animations: node translation channels sampled at a time, so a scene (its objects
//! and its camera) can be rendered at any instant of an exposure.
//!
//! glTF 2.0 §3.11 ("Animations"): a channel targets one property of one node; its sampler
//! holds keyframe times (s, strictly increasing) and values. `LINEAR` interpolates the
//! translation linearly between the two keyframes around t, `STEP` holds the value of the last
//! keyframe at or before t; before the first keyframe and after the last the value is the
//! first / last keyframe's (the specification's clamping). `CUBICSPLINE` and rotation, scale
//! and morph-weight channels are refused with one error line naming the channel: the motion
//! model of camsim is translation (camera and objects), which a rigid motion within one
//! exposure is to first order.
use crate::error::RenderError;
use std::collections::HashMap;
use std::path::Path;

/// How a translation track interpolates between keyframes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Interpolation {
    /// Linear between keyframes.
    Linear,
    /// Piecewise constant (the last keyframe at or before t).
    Step,
}

/// One translation channel: keyframe times and node translations.
#[derive(Debug, Clone, PartialEq)]
pub struct TranslationTrack {
    /// Index of the animated node.
    pub node: usize,
    /// Keyframe times (s), strictly increasing.
    pub times_s: Vec<f64>,
    /// Node translation at each keyframe (m, in the parent's frame).
    pub translations_m: Vec<[f64; 3]>,
    /// Interpolation between keyframes.
    pub interpolation: Interpolation,
}

impl TranslationTrack {
    /// The translation at time `t_s` (glTF 2.0 §3.11.2: clamped outside the keyframes).
    pub fn at(&self, t_s: f64) -> [f64; 3] {
        let (ts, vs) = (&self.times_s, &self.translations_m);
        let n = ts.len();
        if t_s <= ts[0] || n == 1 {
            return vs[0];
        }
        if t_s >= ts[n - 1] {
            return vs[n - 1];
        }
        // last keyframe at or before t
        let k = ts.partition_point(|&x| x <= t_s) - 1;
        match self.interpolation {
            Interpolation::Step => vs[k],
            Interpolation::Linear => {
                let u = (t_s - ts[k]) / (ts[k + 1] - ts[k]);
                std::array::from_fn(|i| vs[k][i] + u * (vs[k + 1][i] - vs[k][i]))
            }
        }
    }
}

/// The translation tracks of every animation of a document (`buffers` as loaded, indexed like
/// the document's buffers). Errors name the file, the animation and the channel.
pub fn translation_tracks(
    path: &Path,
    doc: &gltf::Document,
    buffers: &[gltf::buffer::Data],
) -> Result<Vec<TranslationTrack>, RenderError> {
    let err = |msg: String| RenderError::Scene {
        path: path.display().to_string(),
        msg,
    };
    let mut tracks = Vec::new();
    for anim in doc.animations() {
        for (ci, ch) in anim.channels().enumerate() {
            let what = format!("animations[{}].channels[{ci}]", anim.index());
            let node = ch.target().node().index();
            let interpolation = match ch.sampler().interpolation() {
                gltf::animation::Interpolation::Linear => Interpolation::Linear,
                gltf::animation::Interpolation::Step => Interpolation::Step,
                gltf::animation::Interpolation::CubicSpline => {
                    return Err(err(format!(
                    "{what}: interpolation CUBICSPLINE is not supported (expected LINEAR or STEP)"
                )))
                }
            };
            let reader = ch.reader(|b| buffers.get(b.index()).map(|v| &v[..]));
            let times_s: Vec<f64> = reader
                .read_inputs()
                .ok_or_else(|| err(format!("{what}: sampler input cannot be read")))?
                .map(|t| t as f64)
                .collect();
            let translations_m: Vec<[f64; 3]> = match reader.read_outputs() {
                Some(gltf::animation::util::ReadOutputs::Translations(it)) => {
                    it.map(|v| v.map(|x| x as f64)).collect()
                }
                Some(_) => {
                    return Err(err(format!(
                    "{what}: path \"{}\" is not supported (camsim animates node translation only)",
                    match ch.target().property() {
                        gltf::animation::Property::Rotation => "rotation",
                        gltf::animation::Property::Scale => "scale",
                        gltf::animation::Property::MorphTargetWeights => "weights",
                        gltf::animation::Property::Translation => "translation",
                    }
                )))
                }
                None => return Err(err(format!("{what}: sampler output cannot be read"))),
            };
            if times_s.is_empty() || times_s.len() != translations_m.len() {
                return Err(err(format!(
                    "{what}: {} keyframe times but {} translations (need as many, at least one)",
                    times_s.len(),
                    translations_m.len()
                )));
            }
            if let Some(i) = (0..times_s.len())
                .find(|&i| !times_s[i].is_finite() || (i > 0 && times_s[i] <= times_s[i - 1]))
            {
                return Err(err(format!(
                    "{what}: keyframe time {} at index {i} (times must be finite and strictly increasing)",
                    times_s[i]
                )));
            }
            if translations_m.iter().flatten().any(|v| !v.is_finite()) {
                return Err(err(format!("{what}: a translation is not finite")));
            }
            if tracks.iter().any(|t: &TranslationTrack| t.node == node) {
                return Err(err(format!(
                    "{what}: node {node} already has a translation channel"
                )));
            }
            tracks.push(TranslationTrack {
                node,
                times_s,
                translations_m,
                interpolation,
            });
        }
    }
    Ok(tracks)
}

/// The translation of every animated node at time `t_s` (node index → translation, m).
pub fn translations_at(tracks: &[TranslationTrack], t_s: f64) -> HashMap<usize, [f64; 3]> {
    tracks.iter().map(|t| (t.node, t.at(t_s))).collect()
}
