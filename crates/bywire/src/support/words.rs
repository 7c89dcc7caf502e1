//! Counts in words: "1 file", "2 files".

/// `n` and `noun`, the noun plural unless `n` is 1 (nouns here take an `s`).
pub fn counted(n: impl TryInto<u64>, noun: &str) -> String {
    // Counts of things in memory or on disk: any integer type, none beyond u64.
    let n = n.try_into().unwrap_or(u64::MAX);
    if n == 1 {
        format!("1 {noun}")
    } else {
        format!("{n} {noun}s")
    }
}

#[cfg(test)]
mod tests {
    use super::counted;

    #[test]
    fn one_is_singular_and_every_other_count_plural() {
        assert_eq!(counted(1u64, "file"), "1 file");
        assert_eq!(counted(0u64, "file"), "0 files");
        assert_eq!(counted(2u32, "thread"), "2 threads");
    }
}
