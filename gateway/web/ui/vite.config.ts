import { defineConfig } from 'vite';

// The gateway embeds dist/ into its binary and serves it offline: everything the page
// needs is bundled, nothing is fetched from elsewhere.
export default defineConfig({
  base: '/',
  build: {
    outDir: 'dist',
    emptyOutDir: true,
    target: 'es2022',
    assetsInlineLimit: 0,
    reportCompressedSize: false,
  },
});
