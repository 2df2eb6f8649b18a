//! Scan conversion for chiaro: z-buffer, flat/Gouraud/Phong, shadows, transparency, texture/bump/environment maps.
