//! Byte encoding of what crosses process boundaries: states, payloads,
//! samples and per-chain results. Little-endian, no framing beyond vector
//! lengths; the same binary on every rank is checked at start-up, so no
//! versioning is needed.

use super::DistributedError;
use crate::replica::Tempered;
use crate::sample::Sample;

/// A value that can be sent to another process.
pub trait Wire: Sized {
    /// Appends the encoding of `self` to `out`.
    fn put(&self, out: &mut Vec<u8>);
    /// Decodes one value from the front of `input`, advancing it.
    fn take(input: &mut &[u8]) -> Result<Self, DistributedError>;
}

/// The encoding of `value`.
pub fn encode<T: Wire>(value: &T) -> Vec<u8> {
    let mut out = Vec::new();
    value.put(&mut out);
    out
}

/// Decodes a whole buffer as one `T` (trailing bytes are an error).
pub fn decode<T: Wire>(mut bytes: &[u8]) -> Result<T, DistributedError> {
    let v = T::take(&mut bytes)?;
    if !bytes.is_empty() {
        return Err(DistributedError::Wire(format!(
            "{} trailing bytes after a value",
            bytes.len()
        )));
    }
    Ok(v)
}

fn take_array<const N: usize>(input: &mut &[u8]) -> Result<[u8; N], DistributedError> {
    if input.len() < N {
        return Err(DistributedError::Wire(format!(
            "message ended: needed {N} more bytes, had {}",
            input.len()
        )));
    }
    let (head, rest) = input.split_at(N);
    *input = rest;
    Ok(head.try_into().expect("split at N"))
}

impl Wire for f64 {
    fn put(&self, out: &mut Vec<u8>) {
        out.extend_from_slice(&self.to_bits().to_le_bytes());
    }
    fn take(input: &mut &[u8]) -> Result<Self, DistributedError> {
        Ok(f64::from_bits(u64::from_le_bytes(take_array(input)?)))
    }
}

impl Wire for u64 {
    fn put(&self, out: &mut Vec<u8>) {
        out.extend_from_slice(&self.to_le_bytes());
    }
    fn take(input: &mut &[u8]) -> Result<Self, DistributedError> {
        Ok(u64::from_le_bytes(take_array(input)?))
    }
}

impl Wire for usize {
    fn put(&self, out: &mut Vec<u8>) {
        (*self as u64).put(out);
    }
    fn take(input: &mut &[u8]) -> Result<Self, DistributedError> {
        let v = u64::take(input)?;
        usize::try_from(v).map_err(|_| DistributedError::Wire(format!("{v} overflows usize")))
    }
}

impl Wire for bool {
    fn put(&self, out: &mut Vec<u8>) {
        out.push(*self as u8);
    }
    fn take(input: &mut &[u8]) -> Result<Self, DistributedError> {
        match take_array::<1>(input)?[0] {
            0 => Ok(false),
            1 => Ok(true),
            b => Err(DistributedError::Wire(format!("{b} is not a boolean"))),
        }
    }
}

impl Wire for () {
    fn put(&self, _out: &mut Vec<u8>) {}
    fn take(_input: &mut &[u8]) -> Result<Self, DistributedError> {
        Ok(())
    }
}

impl<T: Wire> Wire for Vec<T> {
    fn put(&self, out: &mut Vec<u8>) {
        self.len().put(out);
        for v in self {
            v.put(out);
        }
    }
    fn take(input: &mut &[u8]) -> Result<Self, DistributedError> {
        let n = usize::take(input)?;
        // Every element takes at least one byte except `()`: cap the
        // reservation so a corrupt length cannot exhaust memory.
        let mut v = Vec::with_capacity(n.min(input.len()));
        for _ in 0..n {
            v.push(T::take(input)?);
        }
        Ok(v)
    }
}

impl<A: Wire, B: Wire> Wire for (A, B) {
    fn put(&self, out: &mut Vec<u8>) {
        self.0.put(out);
        self.1.put(out);
    }
    fn take(input: &mut &[u8]) -> Result<Self, DistributedError> {
        Ok((A::take(input)?, B::take(input)?))
    }
}

impl<P: Wire> Wire for Tempered<P> {
    fn put(&self, out: &mut Vec<u8>) {
        self.log_likelihood.put(out);
        self.log_prior.put(out);
        self.inner.put(out);
    }
    fn take(input: &mut &[u8]) -> Result<Self, DistributedError> {
        Ok(Tempered {
            log_likelihood: f64::take(input)?,
            log_prior: f64::take(input)?,
            inner: P::take(input)?,
        })
    }
}

impl<S: Wire, P: Wire> Wire for Sample<S, P> {
    fn put(&self, out: &mut Vec<u8>) {
        self.state.put(out);
        self.log_density.put(out);
        self.payload.put(out);
    }
    fn take(input: &mut &[u8]) -> Result<Self, DistributedError> {
        Ok(Sample {
            state: S::take(input)?,
            log_density: f64::take(input)?,
            payload: P::take(input)?,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn samples_round_trip_bit_exactly() {
        let s = Sample {
            state: vec![1.5, -0.0, f64::MIN_POSITIVE, f64::NAN],
            log_density: -1e300,
            payload: Tempered {
                log_likelihood: f64::NEG_INFINITY,
                log_prior: 0.25,
                inner: (),
            },
        };
        let back: Sample<Vec<f64>, Tempered<()>> = decode(&encode(&s)).unwrap();
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&back.state), bits(&s.state));
        assert_eq!(back.log_density.to_bits(), s.log_density.to_bits());
        assert_eq!(back.payload.log_likelihood, f64::NEG_INFINITY);
        assert_eq!(back.payload.log_prior, 0.25);
    }

    #[test]
    fn truncated_and_padded_messages_are_errors() {
        let bytes = encode(&vec![1.0f64, 2.0]);
        assert!(decode::<Vec<f64>>(&bytes[..bytes.len() - 1]).is_err());
        let mut long = bytes.clone();
        long.push(0);
        assert!(decode::<Vec<f64>>(&long).is_err());
        assert!(decode::<bool>(&[2]).is_err());
    }
}
