//! What the command's process tests share: starting `autoplug` and reading the address it
//! prints.

use std::io::{BufRead, BufReader};
use std::process::{Child, Command};
use std::thread;

/// A running `autoplug` and the address it printed; killed when dropped.
pub struct Running {
    pub child: Child,
    pub addr: String,
}

impl Drop for Running {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Starts `command` (its standard output piped) and waits for the line that gives its
/// address, `PREFIX ADDR SUFFIX`; the lines after it are read and dropped.
pub fn launch(mut command: Command, prefix: &str, suffix: &str) -> Running {
    let mut child = command.spawn().expect("autoplug runs");
    let stdout = child.stdout.take().expect("stdout");
    let mut lines = BufReader::new(stdout).lines();
    let addr = lines
        .by_ref()
        .map_while(Result::ok)
        .find_map(|line| {
            line.strip_prefix(prefix)
                .and_then(|rest| rest.strip_suffix(suffix))
                .map(str::to_string)
        })
        .unwrap_or_else(|| panic!("the address is printed ({prefix}ADDR{suffix})"));
    // Keep reading: a closed pipe would end the program at its next line of output.
    thread::spawn(move || lines.for_each(drop));
    Running { child, addr }
}

/// Starts `autoplug dashboard ... --token TOKEN` (its output piped) and waits for the
/// page's address it prints.
#[allow(dead_code)] // not every test file starts a dashboard
pub fn launch_dashboard(command: Command, token: &str) -> Running {
    launch(command, "dashboard on http://", &format!("/#token={token}"))
}
