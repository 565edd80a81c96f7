//! Between the core's prepared [`Template`] and the file's [`PreparedTemplate`].
//!
//! A prepared template holds exactly what [`register`](ribreg_core::registration::pipeline::register)
//! reads of an improved-method template (the parts [`Template::from_parts`] takes), so a
//! registration from the file equals one from the cloud bit for bit (tested in
//! `crate::register`).

use crate::io::prepared::PreparedTemplate;
use crate::io::Cloud;
use ribreg_core::math::geom::Frame;
use ribreg_core::registration::pipeline::Template;
use ribreg_core::{Error, Vec3};

/// The file form of `template`, an improved-method template prepared from `cloud`.
pub fn to_file(cloud: &Cloud, template: &Template) -> PreparedTemplate {
    let f = &template.graph.frame;
    PreparedTemplate {
        cloud: cloud.clone(),
        nodes: template
            .graph
            .som1
            .iter()
            .map(|p| [p.x, p.y, p.z])
            .collect(),
        node_labels: template.node_labels.to_vec(),
        skeleton: std::array::from_fn(|i| {
            let p = template.skeleton.points[i];
            [p.x, p.y, p.z]
        }),
        frame_origin: [f.origin.x, f.origin.y, f.origin.z],
        frame_axes: std::array::from_fn(|i| f.axes[(i / 3, i % 3)]),
        frame_spread: [f.spread.x, f.spread.y, f.spread.z],
        midline_fraction: template.midline_fraction,
    }
}

/// The core template of a prepared file, validated by [`Template::from_parts`].
///
/// # Errors
/// The core's refusals of the parts (too many nodes, an improper frame, fractions
/// outside [0, 1], ...).
pub fn from_file(p: &PreparedTemplate) -> Result<Template, Error> {
    let v = |a: &[f32; 3]| Vec3::new(a[0], a[1], a[2]);
    let nodes: Vec<Vec3> = p.nodes.iter().map(v).collect();
    let frame = Frame {
        origin: v(&p.frame_origin),
        axes: nalgebra::Matrix3::from_fn(|r, c| p.frame_axes[3 * r + c]),
        spread: v(&p.frame_spread),
    };
    Template::from_parts(
        &nodes,
        &p.node_labels,
        frame,
        std::array::from_fn(|i| v(&p.skeleton[i])),
        p.midline_fraction,
    )
}
