//! The server's request slots, advice first: an advice request has a core deadline, a message's
//! parse or an eHMI phrasing does not, so a routine call that waits for a slot lets every
//! waiting advice request go before it, for at most 2 s. A call already in flight is not
//! interrupted.

use std::sync::atomic::{AtomicUsize, Ordering};

use tokio::sync::{Notify, Semaphore, SemaphorePermit};
use tokio::time::Instant;

/// Longest a routine call lets advice requests go first.
const ROUTINE_PATIENCE: std::time::Duration = std::time::Duration::from_secs(2);

/// `max_in_flight` slots shared by urgent (advice) and routine calls.
pub struct Slots {
    sem: Semaphore,
    /// Urgent calls waiting for a slot.
    urgent_waiting: AtomicUsize,
    /// Signalled each time an urgent call stops waiting.
    urgent_left: Notify,
}

impl Slots {
    pub fn new(max_in_flight: usize) -> Self {
        Slots {
            sem: Semaphore::new(max_in_flight),
            urgent_waiting: AtomicUsize::new(0),
            urgent_left: Notify::new(),
        }
    }

    /// A slot for an advice request, before every routine call waiting, or `None` if none
    /// frees up before `deadline`.
    pub async fn urgent(&self, deadline: Instant) -> Option<SemaphorePermit<'_>> {
        self.urgent_waiting.fetch_add(1, Ordering::SeqCst);
        let permit = tokio::time::timeout_at(deadline, self.sem.acquire()).await;
        self.urgent_waiting.fetch_sub(1, Ordering::SeqCst);
        self.urgent_left.notify_waiters();
        permit.ok()?.ok()
    }

    /// A slot once no advice request waits for one, or `None` if none is left before
    /// `deadline`.
    pub async fn routine(&self, deadline: Instant) -> Option<SemaphorePermit<'_>> {
        // After `ROUTINE_PATIENCE` it stops deferring: advice asked for every cycle must not
        // starve a message's parse.
        let defer_until = Instant::now() + ROUTINE_PATIENCE;
        let deferring =
            || self.urgent_waiting.load(Ordering::SeqCst) > 0 && Instant::now() < defer_until;
        tokio::time::timeout_at(deadline, async {
            loop {
                // Registered before the check, so that no signal falls between the two.
                let left = self.urgent_left.notified();
                if !deferring() {
                    let permit = self.sem.acquire().await.ok()?;
                    if !deferring() {
                        return Some(permit);
                    }
                    // An urgent call queued behind this one while it waited: it goes first.
                    drop(permit);
                }
                let _ = tokio::time::timeout_at(defer_until, left).await;
            }
        })
        .await
        .ok()?
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Arc;
    use std::time::Duration;

    type Order = Arc<std::sync::Mutex<Vec<&'static str>>>;

    /// A call `name` (advice when `urgent`) that waits for a slot until `deadline`, records its
    /// turn in `order` and holds the slot for 10 ms.
    fn contender(
        slots: &Arc<Slots>,
        order: &Order,
        deadline: Instant,
        name: &'static str,
        urgent: bool,
    ) -> tokio::task::JoinHandle<()> {
        let (slots, order) = (slots.clone(), order.clone());
        tokio::spawn(async move {
            let p = if urgent {
                slots.urgent(deadline).await
            } else {
                slots.routine(deadline).await
            };
            assert!(p.is_some(), "{name} got no slot");
            order.lock().unwrap().push(name);
            tokio::time::sleep(Duration::from_millis(10)).await;
        })
    }

    #[tokio::test(start_paused = true)]
    async fn advice_waiting_goes_before_routine_calls_queued_earlier() {
        let slots = Arc::new(Slots::new(1));
        let far = Instant::now() + Duration::from_secs(60);
        let order = Arc::new(std::sync::Mutex::new(Vec::new()));
        let held = slots.routine(far).await.unwrap();
        let spawn = |name, urgent| contender(&slots, &order, far, name, urgent);
        let routine = spawn("routine", false);
        tokio::time::sleep(Duration::from_millis(1)).await;
        let advice = spawn("advice", true);
        tokio::time::sleep(Duration::from_millis(1)).await;
        drop(held);
        advice.await.unwrap();
        routine.await.unwrap();
        assert_eq!(*order.lock().unwrap(), ["advice", "routine"]);
    }

    #[tokio::test(start_paused = true)]
    async fn after_its_patience_a_routine_call_goes_before_later_advice() {
        let slots = Arc::new(Slots::new(1));
        let far = Instant::now() + Duration::from_secs(60);
        let order = Arc::new(std::sync::Mutex::new(Vec::new()));
        let held = slots.urgent(far).await.unwrap();
        let spawn = |name, urgent| contender(&slots, &order, far, name, urgent);
        let first = spawn("advice 1", true);
        tokio::time::sleep(Duration::from_millis(1)).await;
        let routine = spawn("routine", false);
        tokio::time::sleep(ROUTINE_PATIENCE + Duration::from_secs(1)).await;
        let second = spawn("advice 2", true);
        tokio::time::sleep(Duration::from_millis(1)).await;
        drop(held);
        for t in [first, routine, second] {
            t.await.unwrap();
        }
        assert_eq!(*order.lock().unwrap(), ["advice 1", "routine", "advice 2"]);
    }

    #[tokio::test(start_paused = true)]
    async fn a_slot_that_does_not_free_up_in_time_is_none() {
        let slots = Slots::new(1);
        let soon = Instant::now() + Duration::from_millis(50);
        let _held = slots.urgent(soon).await.unwrap();
        assert!(slots.urgent(soon).await.is_none());
        assert!(slots.routine(soon).await.is_none());
        // Neither timed-out waiter is left counted as waiting.
        assert_eq!(slots.urgent_waiting.load(Ordering::SeqCst), 0);
    }
}
