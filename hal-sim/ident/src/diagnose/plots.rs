//! Plots a person looks at: measured and modelled loops before and after the extension, and
//! the residual against the signal that gave the cause away.

use std::path::{Path, PathBuf};

use super::{evidence, model::own_input, Diagnosis, Signals};
use crate::plot::{write_grid, Plot};

/// Writes one SVG page per output into `dir`; returns the paths.
pub fn write(dir: &Path, d: &Diagnosis, valid: &Signals) -> anyhow::Result<Vec<PathBuf>> {
    std::fs::create_dir_all(dir)
        .map_err(|e| anyhow::anyhow!("cannot create {}: {e}", dir.display()))?;
    let base = d.base.predict(valid);
    let ext = d.extended.predict(valid);
    let valid = &valid.scored();
    let first = d.findings.first().map(|f| f.cause);
    let label = d.extended.causes.label();
    let mut paths = Vec::new();
    for i in 0..valid.y.len() {
        let a = own_input(i, valid.u.len());
        let u = &valid.u[a];
        let y = &valid.y[i];
        let r_base: Vec<f64> = y.iter().zip(&base[i]).map(|(a, b)| a - b).collect();
        let r_ext: Vec<f64> = y.iter().zip(&ext[i]).map(|(a, b)| a - b).collect();
        let (sig_name, sig) = evidence::signal(valid, i, first, &base[i]);
        let (un, yn) = (format!("u{} [V]", a + 1), format!("y{} [um]", i + 1));
        let plots = vec![
            Plot::new(&format!("y{}: base model (cbw)", i + 1), &un, &yn)
                .line("measured", u, y)
                .line("cbw", u, &base[i]),
            Plot::new(&format!("y{}: extended ({label})", i + 1), &un, &yn)
                .line("measured", u, y)
                .line(&label, u, &ext[i]),
            Plot::new(
                &format!(
                    "residual vs the signature of {}",
                    first.map_or("none", |c| c.name())
                ),
                &sig_name,
                "residual [um]",
            )
            .points("base", &sig, &r_base)
            .points("extended", &sig, &r_ext),
            Plot::new("residual in time", "t [s]", "residual [um]")
                .line("base", &valid.t, &r_base)
                .line("extended", &valid.t, &r_ext),
        ];
        let name = if valid.y.len() == 1 {
            "diagnose.svg".to_string()
        } else {
            format!("diagnose_y{}.svg", i + 1)
        };
        let path = dir.join(name);
        write_grid(&path, &plots, 2)
            .map_err(|e| anyhow::anyhow!("cannot write {}: {e}", path.display()))?;
        paths.push(path);
    }
    Ok(paths)
}
