//! FFT-friendly transform sizes.

/// The smallest `m ≥ n` (and ≥ 1) of the form 2^a 3^b 5^c: a size the mixed-radix FFTs
/// (`rustfft`, `realfft`) transform fast.
pub fn next_smooth(n: usize) -> usize {
    let mut m = n.max(1);
    loop {
        let mut k = m;
        for p in [2, 3, 5] {
            while k % p == 0 {
                k /= p;
            }
        }
        if k == 1 {
            return m;
        }
        m += 1;
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn smooth_sizes() {
        let got: Vec<usize> = [0, 1, 7, 11, 13, 97, 1025]
            .iter()
            .map(|&n| super::next_smooth(n))
            .collect();
        assert_eq!(got, vec![1, 1, 8, 12, 15, 100, 1080]);
    }
}
