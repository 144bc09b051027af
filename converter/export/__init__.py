"""3D output: glTF assembly (GltfBuilder) and the GLB writer `facesvg clone` uses."""
