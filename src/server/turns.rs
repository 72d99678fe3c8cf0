//! Round-robin turns on the shared rendering pool.
//!
//! Every session's worker takes a turn before it runs a tick on the pool, and turns are served
//! in the order they were asked for (a ticket lock). A session asks for at most one turn at a
//! time (its worker is one thread), so first come, first served across sessions is
//! round-robin: while another session waits, a session that ticks without pause gets at most
//! every other turn, and the waiting session waits for at most the one tick in progress.
//!
//! Without turns, two sessions' ticks share the pool in rayon's order: its workers steal the
//! running tick's tasks before they look at another session's injected job, and once that job
//! starts, both ticks run at once on the same cores, so a session ticking at 10 Hz next to one
//! spamming ticks waits for the spammer's tick and then takes about twice as long itself.
//! `relume bench fairness` measures the difference.
use std::sync::{Condvar, Mutex, PoisonError};

/// The ticket lock. `next` is the next ticket to hand out; `serving` the ticket whose turn it is.
#[derive(Default)]
pub struct Turns {
    tickets: Mutex<Tickets>,
    turn_over: Condvar,
}

#[derive(Default)]
struct Tickets {
    next: u64,
    serving: u64,
}

/// Ends the turn when dropped, also when the work inside it panicked.
struct Turn<'a>(&'a Turns);

impl Drop for Turn<'_> {
    fn drop(&mut self) {
        let mut t = self.0.tickets.lock().unwrap_or_else(PoisonError::into_inner);
        t.serving += 1;
        self.0.turn_over.notify_all();
    }
}

impl Turns {
    /// Waits for this caller's turn, runs `work`, and passes the turn on.
    pub fn run<R>(&self, work: impl FnOnce() -> R) -> R {
        let mut t = self.tickets.lock().unwrap_or_else(PoisonError::into_inner);
        let ticket = t.next;
        t.next += 1;
        while t.serving != ticket {
            t = self.turn_over.wait(t).unwrap_or_else(PoisonError::into_inner);
        }
        drop(t);
        let _turn = Turn(self);
        work()
    }

    /// Turns asked for and not yet over (the one running included).
    pub fn waiting(&self) -> u64 {
        let t = self.tickets.lock().unwrap_or_else(PoisonError::into_inner);
        t.next - t.serving
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Arc;
    use std::time::Duration;

    /// Waits until `n` turns are asked for (the holder's included).
    fn until_waiting(turns: &Turns, n: u64) {
        while turns.waiting() < n {
            std::thread::sleep(Duration::from_millis(1));
        }
    }

    #[test]
    fn turns_are_served_in_the_order_they_were_asked_for() {
        let turns = Arc::new(Turns::default());
        let order = Arc::new(Mutex::new(Vec::new()));
        let (release, held) = std::sync::mpsc::channel::<()>();
        let holder = {
            let turns = turns.clone();
            std::thread::spawn(move || turns.run(|| held.recv().ok()))
        };
        until_waiting(&turns, 1);
        // Eight threads ask in a known order while the holder keeps the turn.
        let mut threads = Vec::new();
        for i in 0..8u64 {
            let (mine, order) = (turns.clone(), order.clone());
            threads.push(std::thread::spawn(move || mine.run(|| order.lock().unwrap().push(i))));
            until_waiting(&turns, i + 2);
        }
        release.send(()).unwrap();
        holder.join().unwrap();
        for t in threads {
            t.join().unwrap();
        }
        assert_eq!(*order.lock().unwrap(), (0..8).collect::<Vec<_>>());
        assert_eq!(turns.waiting(), 0);
    }

    #[test]
    fn a_panic_inside_a_turn_passes_the_turn_on() {
        let turns = Turns::default();
        let caught = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| turns.run(|| panic!("in the tick"))));
        assert!(caught.is_err());
        // Without the drop guard, this would wait forever for ticket 0's turn to end.
        assert_eq!(turns.run(|| 7), 7);
    }
}
