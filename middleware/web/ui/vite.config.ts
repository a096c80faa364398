import { existsSync, readFileSync } from 'node:fs';
import { join } from 'node:path';
import { defineConfig, type Plugin } from 'vite';

// The bundle carries third-party code (uPlot, MIT licensed), and minifying drops the notices
// its sources hold: each bundled package's licence goes beside the bundle instead, in
// dist/third-party-licenses.txt, which the gateway serves with the page. A few lines of our
// own rather than a plugin package: it needs only the bundler's list of modules per chunk.
function thirdPartyLicenses(): Plugin {
  return {
    name: 'autoplug-third-party-licenses',
    generateBundle(_options, bundle) {
      const packages = new Set<string>();
      for (const chunk of Object.values(bundle)) {
        if (chunk.type !== 'chunk') continue;
        for (const id of chunk.moduleIds) {
          const dir = /^.*[/\\]node_modules[/\\](?:@[^/\\]+[/\\])?[^/\\]+/.exec(id);
          if (dir) packages.add(dir[0].replace(/^\0/, ''));
        }
      }
      const notices = [...packages].map((dir) => {
        const pkg = JSON.parse(readFileSync(join(dir, 'package.json'), 'utf8'));
        const file = ['LICENSE', 'LICENSE.md', 'LICENSE.txt', 'LICENCE', 'license']
          .map((name) => join(dir, name))
          .find((path) => existsSync(path));
        const text = file ? readFileSync(file, 'utf8').trim() : `licence: ${pkg.license}`;
        return `${pkg.name} ${pkg.version} (${pkg.license})\n\n${text}\n`;
      });
      notices.sort();
      this.emitFile({
        type: 'asset',
        fileName: 'third-party-licenses.txt',
        source: `Third-party code in the AutoPlug dashboard's bundle:\n\n${notices.join('\n')}`,
      });
    },
  };
}

// The gateway embeds dist/ into its binary and serves it offline: everything the page
// needs is bundled, nothing is fetched from elsewhere. dist/ is kept in the repository, so
// the main command needs no Node.js; after a change here or in src/, rebuild it with
// scripts/ui-build (CI checks that the kept build is exactly what the sources build).
export default defineConfig({
  base: '/',
  plugins: [thirdPartyLicenses()],
  build: {
    outDir: 'dist',
    emptyOutDir: true,
    target: 'es2022',
    assetsInlineLimit: 0,
    reportCompressedSize: false,
    // The 3-D view's chunk is three.js (about 540 kB), loaded only when the view is chosen;
    // the page itself stays under 200 kB.
    chunkSizeWarningLimit: 600,
  },
});
