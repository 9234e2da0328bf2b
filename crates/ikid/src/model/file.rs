//! The model file's bytes: a safetensors container of F32 tensors in torch's layout plus the
//! card, read from a bounded regular file and written by one function.

use super::card::{CARD_KEY, ModelCard, parse_activation};
use crate::error::{Error, Result};
use crate::features::FeatureSet;
use crate::net::{Affine, Dense, Mlp};
use nalgebra::{DMatrix, DVector};
use safetensors::{Dtype, SafeTensors, tensor::TensorView};
use sha2::{Digest, Sha256};
use std::collections::HashMap;
use std::path::Path;

/// Largest model file [`Model::load`](super::Model::load) reads, bytes. The thesis' largest network is ~0.5 MB;
/// 256 MiB leaves room for any MLP that could run in real time.
pub const MAX_MODEL_FILE_BYTES: u64 = 256 << 20;

/// The bytes of the regular file at `path`, refusing anything else (directory, pipe, device)
/// and anything larger than `limit` before reading it; a file that grows while being read is
/// cut at `limit + 1` bytes and refused.
pub fn read_bounded(path: &Path, limit: u64) -> std::io::Result<Vec<u8>> {
    use std::io::{Error as IoError, ErrorKind as IoKind, Read};
    let meta = std::fs::metadata(path)?;
    if !meta.is_file() {
        let what = if meta.is_dir() { "a directory" } else { "not a regular file (a pipe, socket or device)" };
        return Err(IoError::new(IoKind::InvalidInput, format!("it is {what}; expected a file")));
    }
    let too_large = |size: u64| {
        IoError::new(IoKind::InvalidData, format!("it is {size} bytes, more than the {limit} bytes accepted"))
    };
    if meta.len() > limit {
        return Err(too_large(meta.len()));
    }
    let mut bytes = Vec::with_capacity(meta.len() as usize);
    std::fs::File::open(path)?.take(limit + 1).read_to_end(&mut bytes)?;
    if bytes.len() as u64 > limit {
        return Err(too_large(bytes.len() as u64));
    }
    Ok(bytes)
}

/// Parses and checks a model file's bytes: its card, feature set and network.
pub(super) fn parse(bytes: &[u8]) -> Result<(ModelCard, FeatureSet, Mlp)> {
    let (_, meta) = SafeTensors::read_metadata(bytes).map_err(|e| Error::Container(e.to_string()))?;
    let tensors = SafeTensors::deserialize(bytes).map_err(|e| Error::Container(e.to_string()))?;
    let json = meta.metadata().as_ref().and_then(|m| m.get(CARD_KEY)).ok_or_else(|| {
        Error::ModelCard(format!("the file's __metadata__ has no {CARD_KEY:?} key: not an ikid model file"))
    })?;
    let card = ModelCard::from_json(json)?;
    if let Some(expected) = &card.tensor_sha256 {
        let mut all = tensors.tensors();
        all.sort_by(|a, b| a.0.cmp(&b.0));
        let found = tensor_sha256(all.iter().map(|(n, t)| (n.as_str(), t.dtype(), t.shape(), t.data())));
        if &found != expected {
            return Err(Error::ChecksumMismatch { expected: expected.clone(), found });
        }
    }
    let set = FeatureSet::from_name(&card.feature_set)?;
    let n_in = card.window * set.feature_len();
    let n_layers = card.activations.len();

    let mut used = Vec::new();
    let mut get = |name: String, shape: &[Option<usize>]| -> Result<(Vec<usize>, Vec<f32>)> {
        let t = tensors.tensor(&name).map_err(|_| Error::MissingTensor { name: name.clone() })?;
        let v = read_f32(&name, &t, shape)?;
        used.push(name);
        Ok(v)
    };
    let vector = |(_, v): (Vec<usize>, Vec<f32>)| DVector::from_vec(v);

    let input = Affine {
        scale: vector(get("input.scale".into(), &[Some(n_in)])?),
        shift: vector(get("input.shift".into(), &[Some(n_in)])?),
    };
    let mut layers = Vec::with_capacity(n_layers);
    let mut width = n_in;
    for (k, act) in card.activations.iter().enumerate() {
        let expect_out = (k + 1 == n_layers).then_some(card.outputs.len());
        let (shape, w) = get(format!("layers.{k}.weight"), &[expect_out, Some(width)])?;
        let n_out = shape[0];
        let (_, b) = get(format!("layers.{k}.bias"), &[Some(n_out)])?;
        layers.push(Dense {
            weight: DMatrix::from_row_slice(n_out, width, &w),
            bias: DVector::from_vec(b),
            activation: parse_activation(act).expect("validated with the card"),
        });
        width = n_out;
    }
    let output = Affine {
        scale: vector(get("output.scale".into(), &[Some(width)])?),
        shift: vector(get("output.shift".into(), &[Some(width)])?),
    };
    if let Some(extra) = tensors.names().into_iter().find(|n| !used.iter().any(|u| u == *n)) {
        return Err(Error::UnexpectedTensor { name: extra.to_string() });
    }
    let mlp = Mlp::new(input, layers, output)?;
    Ok((card, set, mlp))
}

fn read_f32(name: &str, t: &TensorView<'_>, expected: &[Option<usize>]) -> Result<(Vec<usize>, Vec<f32>)> {
    if t.dtype() != Dtype::F32 {
        return Err(Error::WrongDtype { name: name.into(), dtype: format!("{:?}", t.dtype()) });
    }
    let shape = t.shape().to_vec();
    let fits =
        shape.len() == expected.len() && shape.iter().zip(expected).all(|(s, e)| e.is_none_or(|e| *s == e) && *s > 0);
    if !fits {
        return Err(Error::ShapeMismatch {
            name: name.into(),
            found: shape,
            expected: expected.iter().map(|e| e.unwrap_or(0)).collect(),
        });
    }
    // `fs::read` gives no alignment guarantee: decode each value (weights are copied once).
    let values: Vec<f32> = t.data().chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect();
    if let Some(index) = values.iter().position(|v| !v.is_finite()) {
        return Err(Error::NonFiniteWeight { name: name.into(), index, value: values[index] });
    }
    Ok((shape, values))
}

/// The checksum a card's `tensor_sha256` holds: SHA-256, as lowercase hex, over the tensors
/// in name order, each as its name, a 0 byte, its dtype's name, a 0 byte, its dimensions and
/// its byte length (u64 little-endian each) and its bytes. Covers names and shapes too, so a
/// renamed or reshaped tensor fails it as well as a flipped bit.
pub fn tensor_sha256<'a>(tensors: impl IntoIterator<Item = (&'a str, Dtype, &'a [usize], &'a [u8])>) -> String {
    let mut hash = Sha256::new();
    for (name, dtype, shape, data) in tensors {
        hash.update(name.as_bytes());
        hash.update([0]);
        hash.update(format!("{dtype:?}").as_bytes());
        hash.update([0]);
        for &d in shape {
            hash.update((d as u64).to_le_bytes());
        }
        hash.update((data.len() as u64).to_le_bytes());
        hash.update(data);
    }
    hash.finalize().iter().map(|b| format!("{b:02x}")).collect()
}

/// Serialises a card and network to `.safetensors` bytes (the one writer of the format),
/// the card's `tensor_sha256` set to the tensors written.
pub fn to_bytes(card: &ModelCard, mlp: &Mlp) -> Result<Vec<u8>> {
    let row_major = |m: &DMatrix<f32>| m.transpose().as_slice().to_vec();
    let mut tensors: Vec<(String, Vec<usize>, Vec<f32>)> = vec![
        ("input.scale".into(), vec![mlp.input.len()], mlp.input.scale.as_slice().to_vec()),
        ("input.shift".into(), vec![mlp.input.len()], mlp.input.shift.as_slice().to_vec()),
        ("output.scale".into(), vec![mlp.output.len()], mlp.output.scale.as_slice().to_vec()),
        ("output.shift".into(), vec![mlp.output.len()], mlp.output.shift.as_slice().to_vec()),
    ];
    for (k, l) in mlp.layers.iter().enumerate() {
        tensors.push((format!("layers.{k}.weight"), vec![l.weight.nrows(), l.weight.ncols()], row_major(&l.weight)));
        tensors.push((format!("layers.{k}.bias"), vec![l.bias.len()], l.bias.as_slice().to_vec()));
    }
    let mut bytes: Vec<(String, Vec<usize>, Vec<u8>)> =
        tensors.into_iter().map(|(n, s, v)| (n, s, v.iter().flat_map(|x| x.to_le_bytes()).collect())).collect();
    bytes.sort_by(|a, b| a.0.cmp(&b.0));
    let mut card = card.clone();
    card.tensor_sha256 =
        Some(tensor_sha256(bytes.iter().map(|(n, s, b)| (n.as_str(), Dtype::F32, s.as_slice(), b.as_slice()))));
    let views = bytes
        .iter()
        .map(|(n, s, b)| {
            Ok((n.as_str(), TensorView::new(Dtype::F32, s.clone(), b).map_err(|e| Error::Container(e.to_string()))?))
        })
        .collect::<Result<Vec<_>>>()?;
    let meta = HashMap::from([(CARD_KEY.to_string(), card.to_json())]);
    safetensors::serialize(views, Some(meta)).map_err(|e| Error::Container(e.to_string()))
}
