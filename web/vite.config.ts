import { defineConfig } from 'vite';

// The console is served by `fmv3d serve` from its asset root; every URL is relative so the
// page works under any mount point, and nothing is fetched from outside the machine.
export default defineConfig({
  base: './',
  build: {
    outDir: process.env.FMV3D_WEB_OUT ?? '../build/web',
    emptyOutDir: true,
    chunkSizeWarningLimit: 2048,
    sourcemap: false,
  },
});
