"""An asset's data as plain arrays and files: mesh, maps, materials, asset folders and files, images."""
