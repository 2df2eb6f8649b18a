//! A progress bar on stderr (indicatif); when stderr is not a terminal (a
//! log, a pipe), a plain line at most once a second instead, the first
//! after a second, so a short run prints nothing. Ctrl-C: the first asks
//! the render to stop (it returns `Cancelled` and nothing is written), a
//! second ends the process.

use chiaro::Progress;
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::io::IsTerminal;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// Set by the first Ctrl-C.
static INTERRUPTED: AtomicBool = AtomicBool::new(false);

/// Exit code of a process stopped by Ctrl-C (128 + SIGINT, as shells report it).
pub const INTERRUPTED_EXIT: u8 = 130;

/// Installs the Ctrl-C handler (a failure only means Ctrl-C kills the
/// process as it would without one).
pub fn handle_interrupt() {
    let _ = ctrlc::set_handler(|| {
        if INTERRUPTED.swap(true, Ordering::SeqCst) {
            std::process::exit(i32::from(INTERRUPTED_EXIT));
        }
    });
}

/// Whether Ctrl-C was pressed.
pub fn interrupted() -> bool {
    INTERRUPTED.load(Ordering::SeqCst)
}

/// Shows each render stage as a bar, or as plain lines (`lines`) when
/// stderr is not a terminal.
#[derive(Debug)]
pub struct Bar {
    bar: ProgressBar,
    lines: Option<Ticker>,
}

/// What the plain lines show: the stage, its position and the last
/// message.
#[derive(Debug, Default)]
struct Lines {
    stage: String,
    pos: u64,
    len: u64,
    message: String,
    /// Set by `Bar::finish`: nothing is printed after it.
    done: bool,
}

/// A thread that prints the plain line once a second (also through a
/// long stage that reports nothing), until `stop`.
#[derive(Debug)]
struct Ticker {
    state: Arc<Mutex<Lines>>,
    stop: Arc<AtomicBool>,
    thread: Option<std::thread::JoinHandle<()>>,
}

/// The time between two plain progress lines.
const LINE_EVERY: Duration = Duration::from_secs(1);

impl Ticker {
    fn start() -> Self {
        let state = Arc::new(Mutex::new(Lines::default()));
        let stop = Arc::new(AtomicBool::new(false));
        let (s, st) = (state.clone(), stop.clone());
        let thread = std::thread::Builder::new()
            .name("progress".into())
            .spawn(move || {
                let start = Instant::now();
                let mut next = start + LINE_EVERY;
                loop {
                    // Short sleeps, so that `stop` ends the thread promptly.
                    std::thread::sleep(Duration::from_millis(50));
                    if st.load(Ordering::SeqCst) {
                        return;
                    }
                    let now = Instant::now();
                    if now < next {
                        continue;
                    }
                    next = now + LINE_EVERY;
                    if let Ok(l) = s.lock()
                        && !l.stage.is_empty()
                        && !l.done
                    {
                        let t = now.duration_since(start).as_secs_f64();
                        eprintln!("[{t:5.0} s] {} {}/{} {}", l.stage, l.pos, l.len, l.message);
                    }
                }
            })
            .ok();
        Self {
            state,
            stop,
            thread,
        }
    }

    fn finish(&mut self) {
        self.stop.store(true, Ordering::SeqCst);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

impl Drop for Ticker {
    fn drop(&mut self) {
        self.finish();
    }
}

impl Bar {
    /// A bar on stderr, or plain lines when stderr is not a terminal.
    pub fn new() -> Self {
        let terminal = std::io::stderr().is_terminal();
        let target = if terminal {
            ProgressDrawTarget::stderr()
        } else {
            ProgressDrawTarget::hidden()
        };
        let bar = ProgressBar::with_draw_target(Some(0), target);
        if let Ok(style) = ProgressStyle::with_template(
            "{prefix:>10} [{bar:40}] {pos}/{len} {elapsed_precise} eta {eta} {msg}",
        ) {
            bar.set_style(style.progress_chars("=> "));
        }
        Self {
            bar,
            lines: (!terminal).then(Ticker::start),
        }
    }

    /// Removes the bar from the terminal (or stops the plain lines).
    pub fn finish(&self) {
        self.bar.finish_and_clear();
        self.line(|l| l.done = true);
        if let Some(t) = &self.lines {
            t.stop.store(true, Ordering::SeqCst);
        }
    }

    /// Updates the plain lines' state with `f`.
    fn line(&self, f: impl FnOnce(&mut Lines)) {
        if let Some(t) = &self.lines
            && let Ok(mut l) = t.state.lock()
        {
            f(&mut l);
        }
    }
}

impl Progress for Bar {
    fn begin(&self, stage: &str, total: u64) {
        self.bar.set_prefix(stage.to_string());
        self.bar.set_length(total);
        self.bar.set_position(0);
        self.bar.set_message("");
        self.line(|l| {
            (l.stage, l.pos, l.len) = (stage.to_string(), 0, total);
            l.message.clear();
        });
    }
    fn advance(&self, n: u64) {
        self.bar.inc(n);
        self.line(|l| l.pos = l.pos.saturating_add(n));
    }
    fn message(&self, text: &str) {
        self.bar.set_message(text.to_string());
        self.line(|l| text.clone_into(&mut l.message));
    }
    fn warning(&self, text: &str) {
        self.bar.suspend(|| eprintln!("warning: {text}"));
    }
    fn cancelled(&self) -> bool {
        interrupted()
    }
}
