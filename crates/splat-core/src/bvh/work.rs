//! Work counters of the BVH traversals (the CPU's; the GPU walks the same nodes in the same
//! order, so they are its counts too): how many traversals ran, how many wide nodes they
//! tested, how many leaves they entered and how many primitives they handed their visitor (a
//! particle's hit test, a triangle's). They do not depend on the machine or the thread count,
//! so `splat bench` reports them beside the wall time to compare variants of a method.
//!
//! Each traversal counts in registers and adds its totals to the calling thread's counters once,
//! when it ends: the render pays one thread-local addition a traversal, not one a node.

use std::cell::Cell;

/// Counts of BVH work.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Work {
    /// Traversals (camera, shadow, bounce and mesh rays; a k-buffer pass is one; a ray that
    /// misses the root box is one of one node, the root's).
    pub traversals: u64,
    /// Wide nodes whose four child boxes were tested.
    pub nodes: u64,
    /// Leaves entered.
    pub leaves: u64,
    /// Primitives handed to the visitor (particle or triangle tests).
    pub tests: u64,
}

impl Work {
    const ZERO: Work = Work { traversals: 0, nodes: 0, leaves: 0, tests: 0 };

    /// Bytes the traversals read: every wide node tested (128 bytes) and a `primitive` record a
    /// test.
    pub fn bytes(&self, primitive: usize) -> u64 {
        self.nodes * super::wide::NODE_BYTES as u64 + self.tests * primitive as u64
    }

    /// The sum of two counts.
    pub fn plus(self, other: Work) -> Work {
        Work {
            traversals: self.traversals + other.traversals,
            nodes: self.nodes + other.nodes,
            leaves: self.leaves + other.leaves,
            tests: self.tests + other.tests,
        }
    }
}

thread_local! {
    static WORK: Cell<Work> = const { Cell::new(Work::ZERO) };
}

/// Add one traversal's counts to this thread's.
#[inline]
pub(super) fn record(nodes: u32, leaves: u32, tests: u32) {
    WORK.with(|w| {
        let mut v = w.get();
        v.traversals += 1;
        v.nodes += u64::from(nodes);
        v.leaves += u64::from(leaves);
        v.tests += u64::from(tests);
        w.set(v);
    });
}

/// This thread's counts since its last `take`, which start again from zero. A render on a
/// thread pool sums every thread's (rayon's `ThreadPool::broadcast`).
pub fn take() -> Work {
    WORK.with(|w| w.replace(Work::ZERO))
}
