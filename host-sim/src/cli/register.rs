//! `ribreg register`: its arguments are [`RegisterJob`] (the library's, so tests and
//! benches can build one).

use super::Context;
use ribreg_sim::error::CliError;
use ribreg_sim::register::{self, RegisterJob};

pub fn run(job: &RegisterJob, ctx: &Context) -> Result<(), CliError> {
    let o = register::run(job, &mut |l| ctx.progress(l))?;
    println!(
        "registered {} points: ED {:.2} ± {:.2} mm (max {:.2}), HD {:.2} mm",
        o.registered.len(),
        o.metrics.ed.mean,
        o.metrics.ed.sd,
        o.metrics.ed.max,
        o.metrics.hausdorff
    );
    Ok(())
}
