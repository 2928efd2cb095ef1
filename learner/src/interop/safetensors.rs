//! A safetensors writer (the format of Hugging Face's `safetensors`: an
//! 8-byte little-endian header length, a JSON header naming each tensor's
//! dtype, shape and byte range, padded with spaces to 8 bytes, then the
//! tensors' little-endian bytes back to back), so that PyTorch, NumPy or JAX
//! users load our weights with `safetensors.safe_open` or `load_file`.

use std::collections::BTreeMap;
use std::path::Path;

/// One tensor to write: its name, shape and values (written as F64, or
/// F32 with [`Tensor::f32`]).
#[derive(Debug, Clone)]
pub struct Tensor {
    /// Its name in the file.
    pub name: String,
    /// Its shape (row-major).
    pub shape: Vec<usize>,
    data: Data,
}

#[derive(Debug, Clone)]
enum Data {
    F64(Vec<f64>),
    F32(Vec<f32>),
}

impl Tensor {
    /// An F64 tensor.
    pub fn f64(name: impl Into<String>, shape: &[usize], values: Vec<f64>) -> Self {
        Self::checked(name.into(), shape, values.len(), Data::F64(values))
    }

    /// An F32 tensor.
    pub fn f32(name: impl Into<String>, shape: &[usize], values: Vec<f32>) -> Self {
        Self::checked(name.into(), shape, values.len(), Data::F32(values))
    }

    fn checked(name: String, shape: &[usize], len: usize, data: Data) -> Self {
        assert_eq!(
            shape.iter().product::<usize>(),
            len,
            "tensor {name}: shape {shape:?} does not hold {len} values"
        );
        Self {
            name,
            shape: shape.to_vec(),
            data,
        }
    }

    fn bytes(&self) -> Vec<u8> {
        match &self.data {
            Data::F64(v) => v.iter().flat_map(|x| x.to_le_bytes()).collect(),
            Data::F32(v) => v.iter().flat_map(|x| x.to_le_bytes()).collect(),
        }
    }

    fn dtype(&self) -> &'static str {
        match self.data {
            Data::F64(_) => "F64",
            Data::F32(_) => "F32",
        }
    }
}

/// The file's bytes: `tensors` in order, `metadata` as the header's
/// `__metadata__` (string to string, as the format allows).
pub fn encode(tensors: &[Tensor], metadata: &BTreeMap<String, String>) -> Vec<u8> {
    let mut header = serde_json::Map::new();
    if !metadata.is_empty() {
        header.insert(
            "__metadata__".into(),
            serde_json::to_value(metadata).expect("strings"),
        );
    }
    let mut data = Vec::new();
    for t in tensors {
        let b = t.bytes();
        header.insert(
            t.name.clone(),
            serde_json::json!({
                "dtype": t.dtype(),
                "shape": t.shape,
                "data_offsets": [data.len(), data.len() + b.len()],
            }),
        );
        data.extend_from_slice(&b);
    }
    let mut text = serde_json::Value::Object(header).to_string().into_bytes();
    while !text.len().is_multiple_of(8) {
        text.push(b' ');
    }
    let mut out = Vec::with_capacity(8 + text.len() + data.len());
    out.extend_from_slice(&(text.len() as u64).to_le_bytes());
    out.extend_from_slice(&text);
    out.extend_from_slice(&data);
    out
}

/// Writes [`encode`]'s bytes to `path` (through a temporary file).
pub fn write(
    path: &Path,
    tensors: &[Tensor],
    metadata: &BTreeMap<String, String>,
) -> std::io::Result<()> {
    crate::write_atomic(path, &encode(tensors, metadata))
}

/// Writes `tensors` as `dir/weights` with `spec` in its metadata (key
/// `spec`), and `spec` again, pretty, as `dir/spec_file`: what an export
/// for other tools consists of. Returns both paths.
pub fn write_with_spec(
    dir: &Path,
    weights: &str,
    spec_file: &str,
    tensors: &[Tensor],
    spec: &serde_json::Value,
) -> std::io::Result<[std::path::PathBuf; 2]> {
    let metadata = BTreeMap::from([("spec".to_string(), spec.to_string())]);
    let st = dir.join(weights);
    write(&st, tensors, &metadata)?;
    let sp = dir.join(spec_file);
    let text = serde_json::to_string_pretty(spec).expect("a spec serialises");
    crate::write_atomic(&sp, text.as_bytes())?;
    Ok([st, sp])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_header_names_each_tensors_bytes() {
        let t = [
            Tensor::f64("a", &[2, 2], vec![1.0, 2.0, 3.0, 4.0]),
            Tensor::f32("b", &[3], vec![5.0, 6.0, 7.0]),
        ];
        let bytes = encode(&t, &BTreeMap::from([("k".into(), "v".into())]));
        let n = u64::from_le_bytes(bytes[..8].try_into().unwrap()) as usize;
        assert_eq!(n % 8, 0);
        let header: serde_json::Value = serde_json::from_slice(&bytes[8..8 + n]).unwrap();
        assert_eq!(header["a"]["data_offsets"], serde_json::json!([0, 32]));
        assert_eq!(header["b"]["dtype"], "F32");
        assert_eq!(header["__metadata__"]["k"], "v");
        let data = &bytes[8 + n..];
        assert_eq!(data.len(), 32 + 12);
        assert_eq!(f64::from_le_bytes(data[8..16].try_into().unwrap()), 2.0);
        assert_eq!(f32::from_le_bytes(data[32..36].try_into().unwrap()), 5.0);
    }
}
