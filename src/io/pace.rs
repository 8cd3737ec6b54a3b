//! Waiting for a moment more finely than the runtime's timer: its steps are 1 ms and a sleep
//! ends on the step after the moment, so a slave's turnaround or a line's quiet time slept
//! whole came out up to a millisecond long (a recorded 5.0 ms latency served as 7 ms).

use tokio::time::{Duration, Instant};

/// Sleeps until `at`: the timer for all but the last millisecond, then yields until the moment.
pub async fn wait_until(at: Instant) {
    let coarse = at.checked_sub(Duration::from_millis(1)).unwrap_or(at);
    if Instant::now() < coarse {
        tokio::time::sleep_until(coarse).await;
    }
    while Instant::now() < at {
        tokio::task::yield_now().await;
    }
}
