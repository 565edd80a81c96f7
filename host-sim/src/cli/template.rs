//! `ribreg template`: its arguments are [`TemplateJob`] (the library's, so tests can
//! build one).

use super::Context;
use ribreg_sim::error::CliError;
use ribreg_sim::template::{self, TemplateJob};

pub fn run(job: &TemplateJob, ctx: &Context) -> Result<(), CliError> {
    let o = template::run(job, &mut |l| ctx.progress(l))?;
    let c = o.counts;
    println!(
        "wrote {}: {} points (sternum {}, rib 2 {}, rib 3 {}, rib 4 {}, rib 5 {}){}",
        job.out.display(),
        o.cloud.points.len(),
        c[1],
        c[2],
        c[3],
        c[4],
        c[5],
        job.prepared.as_ref().map_or(String::new(), |p| format!(
            "; prepared template {}",
            p.display()
        ))
    );
    Ok(())
}
