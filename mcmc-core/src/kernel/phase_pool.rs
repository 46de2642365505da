//! Phase-space points of a NUTS transition, kept in a pool and addressed by
//! index, so the tree builder passes indices where it would copy vectors.
//!
//! A leapfrog step writes its new point into a free slot (out of place,
//! [`Hmc::leapfrog_into`](super::Hmc)), and the sub-trees' ends and
//! multinomial samples are reference-counted indices into the pool: taking
//! a sub-tree's sample or ending a tree moves an index, not `3d` numbers.
//! The pool's vectors are kept from one transition to the next, so a
//! transition allocates nothing once the pool has grown to the deepest tree.

/// A point of phase space with its density, gradient, velocity `M⁻¹p` and
/// Hamiltonian.
#[derive(Clone, Debug, Default)]
pub(crate) struct PhasePoint {
    pub x: Vec<f64>,
    pub p: Vec<f64>,
    pub grad: Vec<f64>,
    /// `M⁻¹ p` (the velocity) at the end of the step.
    pub v: Vec<f64>,
    pub lp: f64,
    /// `H = −ln π + ½ pᵀM⁻¹p`, `+∞` when not finite.
    pub h: f64,
}

/// Reference-counted [`PhasePoint`] slots.
#[derive(Clone, Debug, Default)]
pub(crate) struct PointPool {
    points: Vec<PhasePoint>,
    refs: Vec<u32>,
    free: Vec<usize>,
    dim: usize,
}

impl PointPool {
    /// Frees every slot (the start of a transition) for points of dimension
    /// `dim`.
    pub fn reset(&mut self, dim: usize) {
        if dim != self.dim {
            self.points.clear();
            self.refs.clear();
            self.dim = dim;
        }
        self.refs.fill(0);
        self.free.clear();
        self.free.extend((0..self.points.len()).rev());
    }

    /// Frees every slot for points of dimension `dim` and puts `sample`
    /// (position, gradient, `ln π`) in a fresh one, whose index it returns:
    /// the start of a trajectory.
    pub fn reset_to(
        &mut self,
        dim: usize,
        sample: &crate::sample::Sample<Vec<f64>, crate::gradient::GradientPayload>,
    ) -> usize {
        self.reset(dim);
        let i = self.alloc();
        let z = self.get_mut(i);
        z.x.clone_from(&sample.state);
        z.grad.clone_from(&sample.payload.gradient);
        z.lp = sample.log_density;
        i
    }

    /// A free slot (contents unspecified) with one reference.
    pub fn alloc(&mut self) -> usize {
        let i = self.free.pop().unwrap_or_else(|| {
            let d = self.dim;
            self.points.push(PhasePoint {
                x: vec![0.0; d],
                p: vec![0.0; d],
                grad: vec![0.0; d],
                v: vec![0.0; d],
                lp: 0.0,
                h: 0.0,
            });
            self.refs.push(0);
            self.points.len() - 1
        });
        self.refs[i] = 1;
        i
    }

    /// One more reference to slot `i`.
    #[inline]
    pub fn retain(&mut self, i: usize) {
        self.refs[i] += 1;
    }

    /// Drops a reference to slot `i`; the slot is free at zero.
    #[inline]
    pub fn release(&mut self, i: usize) {
        self.refs[i] -= 1;
        if self.refs[i] == 0 {
            self.free.push(i);
        }
    }

    /// The point in slot `i`.
    #[inline]
    pub fn get(&self, i: usize) -> &PhasePoint {
        &self.points[i]
    }

    /// The point in slot `i`, mutably.
    #[inline]
    pub fn get_mut(&mut self, i: usize) -> &mut PhasePoint {
        &mut self.points[i]
    }

    /// Slot `from` to read and a different slot `to` to write.
    #[inline]
    pub fn pair(&mut self, from: usize, to: usize) -> (&PhasePoint, &mut PhasePoint) {
        assert_ne!(from, to, "a leapfrog step writes a new slot");
        if from < to {
            let (a, b) = self.points.split_at_mut(to);
            (&a[from], &mut b[0])
        } else {
            let (a, b) = self.points.split_at_mut(from);
            (&b[0], &mut a[to])
        }
    }

    /// Slots in use (for the tests: a finished transition holds only its
    /// sample).
    #[cfg(test)]
    pub fn in_use(&self) -> usize {
        self.points.len() - self.free.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn slots_are_reused_once_released() {
        let mut pool = PointPool::default();
        pool.reset(3);
        let a = pool.alloc();
        let b = pool.alloc();
        assert_ne!(a, b);
        pool.retain(a);
        pool.release(a);
        assert_eq!(pool.in_use(), 2);
        pool.release(a);
        assert_eq!(pool.in_use(), 1);
        // The freed slot comes back first; nothing new is allocated.
        assert_eq!(pool.alloc(), a);
        assert_eq!(pool.get(b).x.len(), 3);
        let (from, to) = pool.pair(b, a);
        to.x[0] = from.x[0] + 1.0;
        assert_eq!(pool.get(a).x[0], 1.0);
        pool.reset(3);
        assert_eq!(pool.in_use(), 0);
    }
}
