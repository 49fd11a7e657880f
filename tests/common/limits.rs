//! Runs of a crate's binary with their address space and time limited,
//! shared by the crates' long-run tests: a command that kept every row of a
//! long run in memory aborts, an endless or stuck one is killed.

use std::os::unix::process::CommandExt;
use std::process::Command;

/// The binary `bin`, its address space limited to `bytes` (an allocation
/// beyond fails: the run aborts) and its processor and wall-clock time to
/// `seconds`.
pub fn limited(bin: &str, bytes: u64, seconds: u64) -> Command {
    let mut command = Command::new(bin);
    // SAFETY: `alarm` and `setrlimit` are async-signal-safe, as `pre_exec`
    // requires.
    unsafe {
        command.pre_exec(move || {
            libc::alarm(seconds as libc::c_uint);
            for (resource, value) in [(libc::RLIMIT_AS, bytes), (libc::RLIMIT_CPU, seconds)] {
                let limit = libc::rlimit {
                    rlim_cur: value as libc::rlim_t,
                    rlim_max: value as libc::rlim_t,
                };
                if libc::setrlimit(resource, &limit) != 0 {
                    return Err(std::io::Error::last_os_error());
                }
            }
            Ok(())
        });
    }
    command
}
