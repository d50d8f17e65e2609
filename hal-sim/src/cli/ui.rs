//! `piezo ui`: the lab console in a browser ([`crate::console`]), on 127.0.0.1 unless
//! another address is asked for.
//!
//! ```text
//! piezo ui --port /dev/ttyACM0                 # http://127.0.0.1:8080
//! piezo ui --tcp 127.0.0.1:4444 --listen 8081  # the QEMU firmware's UART on TCP
//! piezo ui --port /dev/ttyACM0 --report out/sim # with the report of `piezo sim --out out/sim`
//! ```
use std::net::{IpAddr, Ipv4Addr, SocketAddr};
use std::path::PathBuf;

use anyhow::{bail, Result};

use super::serial::Conn;

#[derive(clap::Args, Debug)]
pub struct Args {
    #[command(flatten)]
    pub conn: Conn,
    /// Port of the console's web server (0: any free port, printed).
    #[arg(long, default_value_t = 8080, value_name = "PORT")]
    pub listen: u16,
    /// Listen on this address instead of 127.0.0.1 (e.g. 0.0.0.0): anyone who reaches it
    /// can drive the stage; the console warns.
    #[arg(long, value_name = "IP")]
    pub bind: Option<IpAddr>,
    /// Folder for the tools' files (identify, diagnose); default a new one in the
    /// temporary directory.
    #[arg(long)]
    pub work: Option<PathBuf>,
    /// A report to link from the page (a folder with the `index.html` that `piezo sim`,
    /// `demo`, `fit` or `diagnose` write with `--out`).
    #[arg(long = "report", value_name = "DIR")]
    pub reports: Vec<PathBuf>,
}

pub fn run(args: Args) -> Result<()> {
    if args.conn.port.is_none() && args.conn.tcp.is_none() {
        bail!("say where the firmware is: --port <device> or --tcp <host:port>");
    }
    for r in &args.reports {
        let index = r.join(crate::report::INDEX);
        anyhow::ensure!(
            index.is_file(),
            "--report {}: no {} there (written by piezo sim, demo, fit or diagnose with --out)",
            r.display(),
            crate::report::INDEX
        );
    }
    let ip = args.bind.unwrap_or(IpAddr::V4(Ipv4Addr::LOCALHOST));
    let work = args
        .work
        .unwrap_or_else(|| std::env::temp_dir().join(format!("piezo-ui-{}", std::process::id())));
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()?;
    rt.block_on(async move {
        let listener = crate::console::bind(SocketAddr::new(ip, args.listen)).await?;
        // The line the CI step and a person look for.
        println!("piezo ui: http://{}/", listener.local_addr()?);
        crate::console::serve(listener, args.conn, work, args.reports).await
    })
}
