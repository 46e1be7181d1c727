//! Reading the converted LPIPS weights (`semdynreg weights fetch`: safetensors, PyTorch
//! names and layouts, float32) with the `safetensors` crate, no tensor framework.

use safetensors::{Dtype, SafeTensors};

/// The tensor `name` as `f32`s, checked to have exactly `shape`.
pub(crate) fn tensor_f32(
    st: &SafeTensors,
    name: &str,
    shape: &[usize],
) -> Result<Vec<f32>, String> {
    let t = st
        .tensor(name)
        .map_err(|_| format!("missing tensor {name}"))?;
    if t.shape() != shape {
        return Err(format!(
            "tensor {name} has shape {:?}, expected {shape:?}",
            t.shape()
        ));
    }
    if t.dtype() != Dtype::F32 {
        return Err(format!("tensor {name} is {:?}, expected F32", t.dtype()));
    }
    // safetensors stores little-endian; the data may be unaligned, so decode bytewise.
    Ok(t.data()
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;
    use safetensors::tensor::TensorView;

    #[test]
    fn reads_f32_and_rejects_wrong_shape_dtype_and_name() {
        let vals = [1.5f32, -2.0, 0.25, 8.0];
        let bytes: Vec<u8> = vals.iter().flat_map(|v| v.to_le_bytes()).collect();
        let half = vec![0u8; 8];
        let views = [
            (
                "w",
                TensorView::new(Dtype::F32, vec![2, 2], &bytes).unwrap(),
            ),
            ("h", TensorView::new(Dtype::F16, vec![4], &half).unwrap()),
        ];
        let file = safetensors::serialize(views, None).unwrap();
        let st = SafeTensors::deserialize(&file).unwrap();
        assert_eq!(tensor_f32(&st, "w", &[2, 2]).unwrap(), vals);
        assert!(tensor_f32(&st, "w", &[4])
            .unwrap_err()
            .contains("shape [2, 2]"));
        assert!(tensor_f32(&st, "h", &[4]).unwrap_err().contains("F16"));
        assert!(tensor_f32(&st, "x", &[1])
            .unwrap_err()
            .contains("missing tensor x"));
    }
}
