//! Several logs as one, in time order: a streaming merge that holds one record per input (a
//! log's own order is kept; among inputs the earliest goes first, the first input on a tie).

use crate::candump::LogRecord;

/// The records of several inputs, merged by timestamp.
pub struct Merged<I: Iterator> {
    inputs: Vec<I>,
    /// The next record of each input (`None`: not read yet or ended).
    heads: Vec<Option<I::Item>>,
    started: bool,
}

/// Merge `inputs` by timestamp. An error from an input comes out when its turn comes (at
/// once, since an error has no time): the caller decides whether to go on.
pub fn merge<I, E>(inputs: Vec<I>) -> Merged<I>
where
    I: Iterator<Item = Result<LogRecord, E>>,
{
    let heads = inputs.iter().map(|_| None).collect();
    Merged {
        inputs,
        heads,
        started: false,
    }
}

impl<I, E> Iterator for Merged<I>
where
    I: Iterator<Item = Result<LogRecord, E>>,
{
    type Item = Result<LogRecord, E>;

    fn next(&mut self) -> Option<Self::Item> {
        if !self.started {
            self.started = true;
            for (head, input) in self.heads.iter_mut().zip(self.inputs.iter_mut()) {
                *head = input.next();
            }
        }
        // The input whose head is earliest (an error first of all).
        let chosen = self
            .heads
            .iter()
            .enumerate()
            .filter_map(|(i, head)| {
                let key = match head.as_ref()? {
                    Err(_) => None,
                    Ok(record) => Some(record.timestamp),
                };
                Some((key, i))
            })
            .min_by(|(a, i), (b, j)| a.cmp(b).then(i.cmp(j)))
            .map(|(_, i)| i)?;
        let next = self.inputs.get_mut(chosen).and_then(Iterator::next);
        self.heads
            .get_mut(chosen)
            .and_then(|head| std::mem::replace(head, next))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use bywire_core::Timestamp;

    fn log(times: &[u64], interface: &str) -> Vec<Result<LogRecord, String>> {
        times
            .iter()
            .map(|t| {
                Ok(LogRecord {
                    timestamp: Timestamp::from_nanos(*t),
                    interface: interface.into(),
                    frame: "123#".parse().unwrap(),
                    direction: None,
                })
            })
            .collect()
    }

    #[test]
    fn inputs_merge_by_time_and_keep_their_order_on_ties() {
        let merged: Vec<(u64, String)> = merge(vec![
            log(&[1, 5, 9], "a").into_iter(),
            log(&[2, 5, 6], "b").into_iter(),
            log(&[], "c").into_iter(),
        ])
        .map(|r| {
            let r = r.unwrap();
            (r.timestamp.as_nanos(), r.interface)
        })
        .collect();
        let expected: Vec<(u64, String)> =
            [(1, "a"), (2, "b"), (5, "a"), (5, "b"), (6, "b"), (9, "a")]
                .iter()
                .map(|(t, i)| (*t, (*i).to_string()))
                .collect();
        assert_eq!(merged, expected);
    }

    #[test]
    fn an_error_comes_out_at_once() {
        let mut bad = log(&[10], "b");
        bad.insert(0, Err("line 1: broken".into()));
        let mut merged = merge(vec![log(&[1, 2], "a").into_iter(), bad.into_iter()]);
        assert_eq!(merged.next().unwrap().unwrap_err(), "line 1: broken");
        assert_eq!(merged.next().unwrap().unwrap().timestamp.as_nanos(), 1);
    }
}
