//! The one progress display of the CLI, behind core's `Progress` trait: an item bar with ETA
//! (indicatif) when stderr is a terminal, plain lines when it is not (a log file, CI, a pipe
//! read by a test), nothing with `--quiet` or `--json`.
//!
//! `fresco run` prints a stage line before each stage ([`stage_line`]); the bars and plain
//! lines of the stage's tasks follow under it, prefixed with the stage's name.

use std::io::{IsTerminal, Write};
use std::sync::Mutex;
use std::time::Instant;

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

/// The stage `fresco run` is in, shown before each task's name; `None` outside `fresco run`.
static STAGE: Mutex<Option<String>> = Mutex::new(None);

/// Sets (or clears) the stage name shown before every task of the bars created afterwards.
pub fn set_stage(name: Option<&str>) {
    if let Ok(mut s) = STAGE.lock() {
        *s = name.map(str::to_string);
    }
}

/// Prints one line about the run's stages on stderr (unless hidden), between bars.
pub fn stage_line(ctx: &crate::Context, line: &str) {
    if !(ctx.quiet || ctx.json) {
        let mut err = std::io::stderr().lock();
        let _ = writeln!(err, "{line}");
    }
}

/// How the bars are drawn.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Mode {
    Hidden,
    Bar,
    Lines,
}

/// A task being reported as plain lines: one at the start, one at the end, and one at each
/// tenth done if [`LINE_INTERVAL_S`] passed since the last.
struct LineTask {
    name: String,
    total: u64,
    done: u64,
    /// Tenths of `total` already printed.
    tenths: u64,
    start: Instant,
    /// When the last line was printed.
    last: Instant,
}

/// Seconds between two progress lines of one task: short tasks print only their start and end.
const LINE_INTERVAL_S: f64 = 2.0;

pub struct Bars {
    mode: Mode,
    bar: Mutex<Option<ProgressBar>>,
    line: Mutex<Option<LineTask>>,
}

impl Bars {
    pub fn new(ctx: &crate::Context) -> Self {
        let mode = if ctx.quiet || ctx.json {
            Mode::Hidden
        } else if std::io::stderr().is_terminal() {
            Mode::Bar
        } else {
            Mode::Lines
        };
        Bars {
            mode,
            bar: Mutex::new(None),
            line: Mutex::new(None),
        }
    }
}

/// The task's name with the current stage before it.
fn label(task: &str) -> String {
    match STAGE.lock().ok().and_then(|s| s.clone()) {
        Some(stage) if stage != task => format!("{stage}: {task}"),
        _ => task.to_string(),
    }
}

fn print_line(text: &str) {
    let mut err = std::io::stderr().lock();
    let _ = writeln!(err, "{text}");
}

/// Seconds left at the mean rate so far, as "12 s" or "3 min".
fn eta(done: u64, total: u64, elapsed: f64) -> String {
    if done == 0 || done >= total {
        return "?".into();
    }
    let left = elapsed / done as f64 * (total - done) as f64;
    if left < 120.0 {
        format!("{left:.0} s")
    } else {
        format!("{:.0} min", left / 60.0)
    }
}

impl fresco_core::Progress for Bars {
    fn begin(&self, task: &str, total: u64) {
        match self.mode {
            Mode::Hidden => {}
            Mode::Lines => {
                let name = label(task);
                if total > 0 {
                    print_line(&format!("  {name}: 0/{total}"));
                } else {
                    print_line(&format!("  {name} ..."));
                }
                if let Ok(mut slot) = self.line.lock() {
                    *slot = Some(LineTask {
                        name,
                        total,
                        done: 0,
                        tenths: 0,
                        start: Instant::now(),
                        last: Instant::now(),
                    });
                }
            }
            Mode::Bar => {
                let bar = if total > 0 {
                    ProgressBar::with_draw_target(Some(total), ProgressDrawTarget::stderr())
                } else {
                    ProgressBar::new_spinner()
                };
                let template = if total > 0 {
                    "  {msg} [{bar:40}] {pos}/{len} ({elapsed}, eta {eta})"
                } else {
                    "  {msg} {spinner} {pos} ({elapsed})"
                };
                if let Ok(style) = ProgressStyle::with_template(template) {
                    bar.set_style(style.progress_chars("=> "));
                }
                bar.set_message(label(task));
                if let Ok(mut slot) = self.bar.lock()
                    && let Some(old) = slot.replace(bar)
                {
                    old.finish_and_clear();
                }
            }
        }
    }
    fn advance(&self, n: u64) {
        match self.mode {
            Mode::Hidden => {}
            Mode::Lines => {
                if let Ok(mut slot) = self.line.lock()
                    && let Some(t) = slot.as_mut()
                {
                    t.done += n;
                    if let Some(tenths) = (t.done * 10).checked_div(t.total) {
                        let tenths = tenths.min(10);
                        if tenths > t.tenths
                            && tenths < 10
                            && t.last.elapsed().as_secs_f64() >= LINE_INTERVAL_S
                        {
                            t.tenths = tenths;
                            t.last = Instant::now();
                            let elapsed = t.start.elapsed().as_secs_f64();
                            print_line(&format!(
                                "  {}: {}/{} ({}%, eta {})",
                                t.name,
                                t.done,
                                t.total,
                                tenths * 10,
                                eta(t.done, t.total, elapsed)
                            ));
                        }
                    }
                }
            }
            Mode::Bar => {
                if let Ok(slot) = self.bar.lock()
                    && let Some(bar) = slot.as_ref()
                {
                    bar.inc(n);
                }
            }
        }
    }
    fn end(&self) {
        match self.mode {
            Mode::Hidden => {}
            Mode::Lines => {
                if let Ok(mut slot) = self.line.lock()
                    && let Some(t) = slot.take()
                {
                    let seconds = t.start.elapsed().as_secs_f64();
                    // A task without a count (a spinner) has nothing to report but its time.
                    print_line(&if t.total == 0 && t.done == 0 {
                        format!("  {}: done in {seconds:.1} s", t.name)
                    } else {
                        format!("  {}: done, {} in {seconds:.1} s", t.name, t.done)
                    });
                }
            }
            Mode::Bar => {
                if let Ok(mut slot) = self.bar.lock()
                    && let Some(bar) = slot.take()
                {
                    bar.finish_and_clear();
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn eta_is_the_mean_rate_times_what_is_left() {
        assert_eq!(eta(1, 4, 10.0), "30 s");
        assert_eq!(eta(1, 3, 120.0), "4 min");
        assert_eq!(eta(0, 4, 1.0), "?");
        assert_eq!(eta(4, 4, 1.0), "?");
    }
}
