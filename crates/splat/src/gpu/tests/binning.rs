//! Scan, radix sort and tile ranges against plain CPU versions.

use super::ctx;
use crate::gpu::kernel::Recorder;
use crate::gpu::prefix_sum::{PrefixSum, ScanArgs};
use crate::gpu::radix_sort::{RadixSort, SortArgs};
use crate::gpu::tile_ranges::{RangeArgs, TileRanges};
use rand::{Rng, SeedableRng};

fn rng(seed: u64) -> rand_pcg::Pcg64 {
    rand_pcg::Pcg64::seed_from_u64(seed)
}

#[test]
fn prefix_sum_matches_cpu() {
    let Some(c) = ctx() else { return };
    let scan = PrefixSum::new(c);
    let mut r = rng(1);
    // 0, 1, one block, block boundary, several levels (> 256² needs 3 levels).
    for &n in &[0usize, 1, 255, 256, 257, 5000, 70_000] {
        let input: Vec<u32> = (0..n).map(|_| r.random_range(0..20)).collect();
        let ib = c.upload("in", &input);
        let ob = c.storage("out", (n as u64 + 1) * 4);
        let mut rec = Recorder::new(c, false);
        scan.dispatch(
            c,
            &mut rec,
            &ScanArgs {
                input: &ib,
                output: &ob,
                n: n as u32,
            },
        )
        .unwrap();
        rec.finish().unwrap();
        let got: Vec<u32> = c.read(&ob, n + 1).unwrap();
        let mut acc = 0u32;
        for i in 0..n {
            assert_eq!(got[i], acc, "n={n} index {i}");
            acc += input[i];
        }
        assert_eq!(got[n], acc, "total for n={n}");
    }
}

#[test]
fn radix_sort_is_stable_and_matches_cpu() {
    let Some(c) = ctx() else { return };
    let scan = PrefixSum::new(c);
    let sort = RadixSort::new(c);
    let mut r = rng(2);
    for &(n, bits) in &[
        (2usize, 32u32),
        (300, 5),
        (1000, 32),
        (20_000, 9),
        (70_001, 32),
    ] {
        // Few distinct keys for small `bits` so stability is exercised.
        let mask = if bits == 32 {
            u32::MAX
        } else {
            (1 << bits) - 1
        };
        let keys: Vec<u32> = (0..n)
            .map(|_| {
                if bits == 32 {
                    r.random::<u32>()
                } else {
                    r.random::<u32>() & mask
                }
            })
            .collect();
        // High garbage bits above `bits` must be ignored: add them for bits < 32.
        let dirty: Vec<u32> = keys
            .iter()
            .map(|k| {
                if bits == 32 {
                    *k
                } else {
                    *k | (r.random::<u32>() << bits)
                }
            })
            .collect();
        let values: Vec<u32> = (0..n as u32).collect();
        let kb = c.upload("k", &dirty);
        let vb = c.upload("v", &values);
        let mut rec = Recorder::new(c, false);
        sort.dispatch(
            c,
            &scan,
            &mut rec,
            &SortArgs {
                keys: &kb,
                values: &vb,
                n: n as u32,
                bits,
            },
        )
        .unwrap();
        rec.finish().unwrap();
        let gk: Vec<u32> = c.read(&kb, n).unwrap();
        let gv: Vec<u32> = c.read(&vb, n).unwrap();
        let mut expect: Vec<(u32, u32)> =
            dirty.iter().copied().zip(values.iter().copied()).collect();
        expect.sort_by_key(|p| p.0 & mask); // stable
        for i in 0..n {
            assert_eq!((gk[i], gv[i]), expect[i], "n={n} bits={bits} index {i}");
        }
    }
}

#[test]
fn tile_ranges_match_cpu() {
    let Some(c) = ctx() else { return };
    let ranges = TileRanges::new(c);
    let mut r = rng(3);
    let num_tiles = 37u32;
    let mut keys: Vec<u32> = (0..3000).map(|_| r.random_range(0..num_tiles)).collect();
    keys.sort();
    let kb = c.upload("k", &keys);
    let rb = c.storage("r", num_tiles as u64 * 8);
    let mut rec = Recorder::new(c, false);
    ranges
        .dispatch(
            c,
            &mut rec,
            &RangeArgs {
                tile_keys: &kb,
                ranges: &rb,
                n: keys.len() as u32,
                num_tiles,
            },
        )
        .unwrap();
    rec.finish().unwrap();
    let got: Vec<u32> = c.read(&rb, num_tiles as usize * 2).unwrap();
    for t in 0..num_tiles {
        let start = keys.partition_point(|&k| k < t) as u32;
        let end = keys.partition_point(|&k| k <= t) as u32;
        let (s, e) = if start == end { (0, 0) } else { (start, end) };
        assert_eq!(
            (got[2 * t as usize], got[2 * t as usize + 1]),
            (s, e),
            "tile {t}"
        );
    }
}

#[test]
fn scratch_is_grow_only_and_reused() {
    let Some(c) = ctx() else { return };
    let mut s = crate::gpu::kernel::Scratch::default();
    let a = s.get(c, "x", 1000);
    assert_eq!(s.allocations, 1);
    assert!(a.size() >= 1500, "1.5x headroom: {}", a.size());
    // Smaller or within the headroom: the same buffer, no allocation.
    let b = s.get(c, "x", 400);
    let d = s.get(c, "x", 1400);
    assert_eq!(s.allocations, 1);
    assert_eq!(a, b);
    assert_eq!(a, d);
    // Another role gets its own buffer.
    let e = s.get(c, "y", 400);
    assert_ne!(a, e);
    assert_eq!(s.allocations, 2);
    // Past capacity: reallocated once, larger.
    let f = s.get(c, "x", 4000);
    assert_eq!(s.allocations, 3);
    assert!(f.size() >= 6000);
    assert_ne!(a, f);
}
