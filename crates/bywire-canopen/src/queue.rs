//! Fixed-capacity queues: nothing on the control path allocates, and what does not fit is
//! counted, never silently lost.

/// A fixed-capacity FIFO (events, frames waiting to be sent) that counts what it had to drop.
#[derive(Debug, Clone)]
pub struct EventQueue<T: Copy, const N: usize> {
    items: [Option<T>; N],
    head: usize,
    len: usize,
    /// Events dropped because the queue was full.
    pub dropped: u64,
}

impl<T: Copy, const N: usize> EventQueue<T, N> {
    /// An empty queue.
    pub fn new() -> Self {
        EventQueue {
            items: [None; N],
            head: 0,
            len: 0,
            dropped: 0,
        }
    }

    /// Add at the back; a full queue drops the newest, counts it and says `false`.
    #[must_use = "a full queue drops the item"]
    pub fn push(&mut self, item: T) -> bool {
        if self.len >= N {
            self.dropped = self.dropped.saturating_add(1);
            return false;
        }
        match self.items.get_mut((self.head + self.len) % N) {
            Some(slot) => {
                *slot = Some(item);
                self.len += 1;
                true
            }
            None => false,
        }
    }

    /// Drop everything waiting.
    pub fn clear(&mut self) {
        while self.pop().is_some() {}
    }

    /// Take from the front.
    pub fn pop(&mut self) -> Option<T> {
        if self.len == 0 {
            return None;
        }
        let item = self.items.get_mut(self.head).and_then(Option::take);
        self.head = (self.head + 1) % N;
        self.len -= 1;
        item
    }

    /// Items waiting.
    pub fn len(&self) -> usize {
        self.len
    }

    /// Nothing waiting.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Room left.
    pub fn room(&self) -> usize {
        N - self.len
    }
}

impl<T: Copy, const N: usize> Default for EventQueue<T, N> {
    fn default() -> Self {
        Self::new()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn event_queue_is_bounded_and_counts_drops() {
        let mut queue: EventQueue<u8, 2> = EventQueue::new();
        let _ = queue.push(1);
        let _ = queue.push(2);
        let _ = queue.push(3);
        assert_eq!(queue.dropped, 1);
        assert_eq!(
            (queue.pop(), queue.pop(), queue.pop()),
            (Some(1), Some(2), None)
        );
    }
}
