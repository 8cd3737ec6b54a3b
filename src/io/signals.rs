//! Stopping: Ctrl-C, SIGTERM, or the terminal UI's `q`. One home for every command and the UI,
//! so a loop anywhere can ask "should I stop?" and a waiting task can await it.

/// Set once something asked the program to stop (a signal, or `q` in the terminal UI).
static STOP_REQUESTED: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);
/// Set when the stop came from SIGTERM or SIGINT (the UI then closes too).
static SIGNALLED: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);
/// Wakes a [`shutdown_signal`] waiting in another thread; a stored permit covers one that is
/// not waiting yet.
static STOP: tokio::sync::Notify = tokio::sync::Notify::const_new();

/// Asks every running [`shutdown_signal`] to fire (the terminal UI's `q`).
pub fn request_stop() {
    STOP_REQUESTED.store(true, std::sync::atomic::Ordering::SeqCst);
    STOP.notify_one();
}

/// Whether a stop was asked for (for loops that do not await).
#[must_use]
pub fn stop_requested() -> bool {
    STOP_REQUESTED.load(std::sync::atomic::Ordering::SeqCst)
}

/// Whether a signal (Ctrl-C outside raw mode, SIGTERM) arrived.
#[must_use]
pub fn signalled() -> bool {
    SIGNALLED.load(std::sync::atomic::Ordering::SeqCst)
}

/// Ctrl-C, SIGTERM, or [`request_stop`].
pub(crate) async fn shutdown_signal() {
    let term = async {
        match tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate()) {
            Ok(mut s) => {
                s.recv().await;
            }
            Err(_) => std::future::pending::<()>().await,
        }
    };
    if stop_requested() {
        return;
    }
    tokio::select! {
        _ = tokio::signal::ctrl_c() => SIGNALLED.store(true, std::sync::atomic::Ordering::SeqCst),
        () = term => SIGNALLED.store(true, std::sync::atomic::Ordering::SeqCst),
        () = STOP.notified() => {}
    }
    STOP_REQUESTED.store(true, std::sync::atomic::Ordering::SeqCst);
    // Another waiter (a second loop in the same run) stops too.
    STOP.notify_one();
}

/// [`shutdown_signal`], or `deadline` (`--duration`) when there is one, whichever comes first.
pub(crate) async fn stop_or_deadline(deadline: Option<tokio::time::Instant>) {
    let at_deadline = async {
        match deadline {
            Some(d) => tokio::time::sleep_until(d).await,
            None => std::future::pending().await,
        }
    };
    tokio::select! {
        () = shutdown_signal() => {}
        () = at_deadline => {}
    }
}
