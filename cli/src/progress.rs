//! Progress bars (indicatif) behind core's `Progress` trait; hidden with `--quiet` or `--json`
//! and when stderr is not a terminal.

use std::sync::Mutex;

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

pub struct Bars {
    hidden: bool,
    bar: Mutex<Option<ProgressBar>>,
}

impl Bars {
    pub fn new(ctx: &crate::Context) -> Self {
        Bars {
            hidden: ctx.quiet || ctx.json,
            bar: Mutex::new(None),
        }
    }
}

impl fresco_core::Progress for Bars {
    fn begin(&self, task: &str, total: u64) {
        let bar = if self.hidden {
            ProgressBar::hidden()
        } else if total > 0 {
            ProgressBar::with_draw_target(Some(total), ProgressDrawTarget::stderr())
        } else {
            ProgressBar::new_spinner()
        };
        let template = if total > 0 {
            "{msg:>12} [{bar:40}] {pos}/{len} ({eta})"
        } else {
            "{msg:>12} {spinner} {pos} ({elapsed})"
        };
        if let Ok(style) = ProgressStyle::with_template(template) {
            bar.set_style(style.progress_chars("=> "));
        }
        bar.set_message(task.to_string());
        if let Ok(mut slot) = self.bar.lock()
            && let Some(old) = slot.replace(bar)
        {
            old.finish_and_clear();
        }
    }
    fn advance(&self, n: u64) {
        if let Ok(slot) = self.bar.lock()
            && let Some(bar) = slot.as_ref()
        {
            bar.inc(n);
        }
    }
    fn end(&self) {
        if let Ok(mut slot) = self.bar.lock()
            && let Some(bar) = slot.take()
        {
            bar.finish_and_clear();
        }
    }
}
