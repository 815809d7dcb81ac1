//! The operator's console: a web page served by mocomp itself, on the application core.
//!
//! [`Console::start`] binds the address (loopback unless allowed otherwise), makes the session's
//! token, and serves the page, its API and its WebSocket ([`api`]) from a thread of its own with
//! a small tokio runtime. The loop is never touched: the console reads what the live loop's
//! logger thread tells its [`state::ConsoleObserver`], and steers the loop through the lock-free
//! [`mocomp_app::frontend::Controls`] (hold, resume, stop, new loop parameters).
//!
//! **Limits.** Changes the running loop only through the application's `Controls`, and only with
//! the session's token; it never reaches the robot itself.

pub mod api;
pub mod auth;
pub mod mri;
pub mod navigation;
pub mod page;
pub mod state;

use auth::{Site, Token};
use mocomp_app::config::Setup;
use mocomp_app::frontend::Controls;
use mocomp_app::robot::collect::Progress;
use state::{CalibrationJson, ConsoleObserver, Frames, Shared};
use std::io::Write;
use std::net::{SocketAddr, TcpListener};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::thread::JoinHandle;
use tokio::sync::oneshot;

/// Where the console listens unless told otherwise.
pub const DEFAULT_ADDR: &str = "127.0.0.1:8080";

/// What goes wrong starting the console.
#[derive(Debug, thiserror::Error)]
pub enum ConsoleError {
    /// A non-loopback address without the explicit permission.
    #[error(
        "--dashboard {0}: not a loopback address; the console would be reachable from the \
         network: pass --dashboard-allow-remote to mean it"
    )]
    Remote(SocketAddr),
    /// The address could not be bound.
    #[error("--dashboard {addr}: cannot listen there")]
    Bind {
        /// The address.
        addr: SocketAddr,
        /// Why.
        #[source]
        source: std::io::Error,
    },
    /// No random token.
    #[error("making the console's token")]
    Random(#[source] getrandom::Error),
    /// The token file could not be written.
    #[error("--dashboard-token-file {path}: cannot write it")]
    TokenFile {
        /// The file.
        path: PathBuf,
        /// Why.
        #[source]
        source: std::io::Error,
    },
    /// The server's thread or runtime could not start.
    #[error("starting the console's server")]
    Server(#[source] std::io::Error),
    /// The session's frames are incomplete.
    #[error(transparent)]
    Setup(#[from] mocomp_app::AppError),
}

/// How the console is started.
#[derive(Debug, Clone)]
pub struct ConsoleOptions {
    /// Where to listen (port 0: any free port; the console says which it got).
    pub addr: SocketAddr,
    /// Allow an address other than loopback.
    pub allow_remote: bool,
    /// Write the token to this file (mode 0600).
    pub token_file: Option<PathBuf>,
}

/// A running console. Dropping it stops the server.
#[derive(Debug)]
pub struct Console {
    addr: SocketAddr,
    token: Token,
    shared: Arc<Shared>,
    frames: Frames,
    shutdown: Option<oneshot::Sender<()>>,
    thread: Option<JoinHandle<()>>,
}

impl Console {
    /// Starts the console for the session on `setup`, steering it through `controls`.
    pub fn start(
        options: &ConsoleOptions,
        setup: &Setup,
        controls: Arc<Controls>,
    ) -> Result<Self, ConsoleError> {
        if !options.addr.ip().is_loopback() && !options.allow_remote {
            return Err(ConsoleError::Remote(options.addr));
        }
        let token = Token::random().map_err(ConsoleError::Random)?;
        if let Some(path) = &options.token_file {
            write_secret(path, token.as_str()).map_err(|source| ConsoleError::TokenFile {
                path: path.clone(),
                source,
            })?;
        }
        let listener = TcpListener::bind(options.addr).map_err(|source| ConsoleError::Bind {
            addr: options.addr,
            source,
        })?;
        let addr = listener.local_addr().map_err(ConsoleError::Server)?;
        listener
            .set_nonblocking(true)
            .map_err(ConsoleError::Server)?;
        // The observer needs the frames: name a missing one now, not once the loop runs.
        let frames = Frames::of(setup)?;
        let shared = Shared::new(setup, controls);
        let app = api::router(api::Api {
            shared: Arc::clone(&shared),
            token: token.clone(),
            site: Site { addr },
        });
        let runtime = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .map_err(ConsoleError::Server)?;
        let (shutdown, stopped) = oneshot::channel::<()>();
        let thread = std::thread::Builder::new()
            .name("mocomp-console".into())
            .spawn(move || {
                // Whatever starts it, the console must not compete with the real-time loop.
                mocomp_rt::set_normal().ok();
                mocomp_rt::unpin().ok();
                runtime.block_on(async move {
                    let Ok(listener) = tokio::net::TcpListener::from_std(listener) else {
                        return;
                    };
                    axum::serve(listener, app)
                        .with_graceful_shutdown(async {
                            stopped.await.ok();
                        })
                        .await
                        .ok();
                });
            })
            .map_err(ConsoleError::Server)?;
        Ok(Self {
            addr,
            token,
            shared,
            frames,
            shutdown: Some(shutdown),
            thread: Some(thread),
        })
    }

    /// The address it listens on.
    pub fn addr(&self) -> SocketAddr {
        self.addr
    }

    /// The session's token.
    pub fn token(&self) -> &Token {
        &self.token
    }

    /// The link an operator opens: it carries the token once, and the page keeps it as a cookie.
    pub fn url(&self) -> String {
        format!("http://{}/?token={}", self.addr, self.token.as_str())
    }

    /// Tells the page how a calibration collection goes (`mocomp calibrate collect
    /// --dashboard`): give it each [`Progress`], then the outcome.
    pub fn calibration_progress(&self, p: &Progress) {
        let mut c = self.calibration();
        let event = match p {
            Progress::Waiting { poses } => {
                c = CalibrationJson {
                    state: "waiting",
                    planned: *poses,
                    done: 0,
                    missed: Vec::new(),
                    message: None,
                };
                Some(format!("{poses} poses planned; waiting for the go"))
            }
            Progress::Planned { poses, .. } => {
                c.state = "collecting";
                c.planned = *poses;
                Some("the arm moves".to_string())
            }
            Progress::Pose { index, seen } => {
                c.done = index + 1;
                if !seen {
                    c.missed.push(index + 1);
                }
                Some(if *seen {
                    format!("pose {} measured", index + 1)
                } else {
                    format!("pose {}: marker not seen", index + 1)
                })
            }
        };
        self.shared.publish_calibration(c, event);
    }

    /// The collection's outcome: `Ok` with a summary, or why it failed.
    pub fn calibration_finished(&self, outcome: Result<String, String>) {
        let mut c = self.calibration();
        let (state, message) = match outcome {
            Ok(m) => ("done", m),
            Err(m) => ("failed", m),
        };
        c.state = state;
        c.message = Some(message.clone());
        self.shared.publish_calibration(c, Some(message));
    }

    /// Tells the page how a navigation task goes (`mocomp register --dashboard`): its whole
    /// progress each time, and what just happened.
    pub fn navigation(&self, n: state::NavigationJson, event: Option<String>) {
        self.shared.publish_navigation(n, event);
    }

    /// The calibration progress published so far.
    fn calibration(&self) -> CalibrationJson {
        self.shared
            .status()
            .calibration
            .unwrap_or_else(|| CalibrationJson {
                state: "waiting",
                planned: 0,
                done: 0,
                missed: Vec::new(),
                message: None,
            })
    }

    /// The observer of one controller's run in the experiment (`mocomp demo --dashboard`): the
    /// scene becomes the experiment's (the coil robot `arm`, the frames it calibrated).
    pub fn experiment_observer(
        &self,
        controller: &'static str,
        arm: mocomp_kin::Arm,
        loop_cfg: &mocomp_control::LoopConfig,
    ) -> ConsoleObserver {
        self.shared.set_scene(arm.model().to_string(), loop_cfg);
        ConsoleObserver::new(Arc::clone(&self.shared), Frames::of_loop(arm, loop_cfg))
            .of_controller(controller)
    }

    /// Shows a phase that is not a loop's (starting, calibrating) as the status.
    pub fn phase(&self, what: &str) {
        self.shared.publish_phase(what);
    }

    /// The observer the live loop tells (give it to [`mocomp_app::live::run`]).
    pub fn observer(&self) -> ConsoleObserver {
        ConsoleObserver::new(Arc::clone(&self.shared), self.frames)
    }
}

/// How long a console that closes waits for its pages to get the last status.
const LINGER: std::time::Duration = std::time::Duration::from_secs(1);

impl Drop for Console {
    fn drop(&mut self) {
        // The last status (stopped, calibrated, failed) reaches the open pages first.
        self.shared.linger(LINGER);
        if let Some(s) = self.shutdown.take() {
            s.send(()).ok();
        }
        if let Some(t) = self.thread.take() {
            t.join().ok();
        }
    }
}

/// Writes `secret` to a new file only its owner may read (0600 from the start, never wider).
fn write_secret(path: &Path, secret: &str) -> std::io::Result<()> {
    use std::os::unix::fs::OpenOptionsExt;
    // A file left from an earlier run may have other permissions: replace it.
    match std::fs::remove_file(path) {
        Err(e) if e.kind() != std::io::ErrorKind::NotFound => return Err(e),
        _ => {}
    }
    let mut f = std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .mode(0o600)
        .open(path)?;
    writeln!(f, "{secret}")?;
    f.sync_all()
}

/// The console shows `mocomp demo`: its phases and each controller's run.
impl mocomp_app::demo::run::DemoFront for Console {
    fn phase(&self, what: &str) {
        Console::phase(self, what);
    }
    fn observer(
        &self,
        controller: &'static str,
        arm: mocomp_kin::Arm,
        loop_cfg: &mocomp_control::LoopConfig,
    ) -> Box<dyn mocomp_app::frontend::Observer> {
        Box::new(self.experiment_observer(controller, arm, loop_cfg))
    }
}
