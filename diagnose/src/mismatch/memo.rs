//! A per-thread, direct-mapped memo of pure functions of a few `f64`s (the censored-normal
//! moments and the rail-count likelihood): on uniform shots (darks at the black rail, flats
//! whose bright pixels clip) most pixel-shots ask for the same value, and each costs dozens of
//! `erfc`/`ln`/`exp`. The key is the arguments' bits, compared in full on a hit, so a hit
//! returns exactly what the function would: the memo changes no bit of any result.
use std::cell::RefCell;

/// Slots per table (a power of two).
const SLOTS: usize = 256;

/// A direct-mapped table from `N` argument bit patterns to a value.
pub(crate) struct Memo<const N: usize, V: Copy> {
    slots: Vec<Option<([u64; N], V)>>,
}

impl<const N: usize, V: Copy> Default for Memo<N, V> {
    fn default() -> Self {
        Memo {
            slots: vec![None; SLOTS],
        }
    }
}

impl<const N: usize, V: Copy> Memo<N, V> {
    /// `f()` for the arguments `args`, from the table when they were the last asked for in
    /// their slot.
    #[inline]
    pub(crate) fn get(&mut self, args: [f64; N], f: impl FnOnce() -> V) -> V {
        let key: [u64; N] = args.map(f64::to_bits);
        // FxHash-style mix of the bits (the slot only: the whole key is compared).
        let mut h: u64 = 0;
        for k in key {
            h = (h.rotate_left(5) ^ k).wrapping_mul(0x51_7c_c1_b7_27_22_0a_95);
        }
        let slot = (h >> 56) as usize % SLOTS;
        if let Some((k, v)) = &self.slots[slot] {
            if *k == key {
                return *v;
            }
        }
        let v = f();
        self.slots[slot] = Some((key, v));
        v
    }
}

/// `f()` memoised per thread in `cell` (see [`Memo`]).
#[inline]
pub(crate) fn memo_with<const N: usize, V: Copy + 'static>(
    cell: &'static std::thread::LocalKey<RefCell<Memo<N, V>>>,
    args: [f64; N],
    f: impl FnOnce() -> V,
) -> V {
    cell.with(|m| match m.try_borrow_mut() {
        Ok(mut m) => m.get(args, f),
        // (re-entered from within f: compute directly)
        Err(_) => f(),
    })
}

#[cfg(test)]
mod tests {
    use super::Memo;

    /// A hit returns the stored value only for the same argument bits (0.0 and −0.0 differ);
    /// colliding keys evict each other and are recomputed.
    #[test]
    fn memo_returns_the_function_value_for_every_key() {
        let mut m: Memo<2, f64> = Memo::default();
        let mut calls = 0;
        let f = |a: f64, b: f64| a * 3.0 - b;
        for round in 0..3 {
            for i in 0..1000 {
                let (a, b) = (i as f64 * 0.37, if i % 2 == 0 { 0.0 } else { -0.0 });
                let v = m.get([a, b], || {
                    calls += 1;
                    f(a, b)
                });
                assert_eq!(v.to_bits(), f(a, b).to_bits(), "round {round} i {i}");
            }
        }
        // 1000 keys in 256 slots: most are recomputed, none returned wrong.
        assert!(calls >= 1000);
        let mut calls2 = 0;
        for _ in 0..10 {
            m.get([1.5, 2.5], || {
                calls2 += 1;
                f(1.5, 2.5)
            });
        }
        assert_eq!(calls2, 1);
    }
}
