// ESLint for the operator dashboard (src/api/dashboard/*.js): plain browser ES modules,
// loaded with <script type="module">, no bundler. rackd itself is Rust; this lints only
// that JavaScript. CI runs: npm ci --no-audit --no-fund && npx --no-install eslint src/api/dashboard
//
// Every rule below is at "error", so any finding fails the run (there are no warnings to
// let through), and a disable comment that no longer suppresses anything is an error too.

import js from '@eslint/js';
import globals from 'globals';

export default [
  {
    files: ['src/api/dashboard/**/*.js'],
    languageOptions: {
      ecmaVersion: 'latest',
      sourceType: 'module',
      globals: { ...globals.browser },
    },
    linterOptions: {
      reportUnusedDisableDirectives: 'error',
    },
    rules: {
      // ESLint's recommended set: undefined names (no-undef), unreachable code, duplicate
      // keys and cases, constant conditions, and the like.
      ...js.configs.recommended.rules,

      // A loose == or != converts types behind one's back; the page compares ids, states and
      // statuses from JSON. (It spells null checks out as === null || === undefined.)
      eqeqeq: ['error', 'always'],

      // var is function-scoped and hoisted; let and const are what the modules use.
      'no-var': 'error',

      // A binding never reassigned is const, so a reassignment that is one stands out.
      'prefer-const': 'error',

      // A dead variable, import or trailing argument is usually a leftover or a typo; the
      // catch binding counts too (the code uses a bare `catch {` where it needs none).
      'no-unused-vars': ['error', { vars: 'all', args: 'after-used', caughtErrors: 'all' }],

      // A local that hides a module-level name (the helpers el, ms, key...) turns a call to
      // the helper into a call to the local. Browser globals are not counted (locals named
      // name, status or event are fine; see the next rule for the other side of that).
      'no-shadow': ['error', { builtinGlobals: false }],

      // With the browser globals declared, no-undef cannot see a reference to a local that
      // is gone: `name`, `status`, `event`... silently become window.name and so on. These
      // are never meant as globals in this code (window.x when they are).
      'no-restricted-globals': [
        'error',
        'event',
        'name',
        'status',
        'length',
        'origin',
        'parent',
        'top',
        'self',
        'close',
        'open',
      ],

      // '${x}' in a plain string is a template literal that lost its backquotes; the page
      // builds most of its text with templates.
      'no-template-curly-in-string': 'error',

      // Not enabled, though sometimes suggested:
      // - no-implicit-globals: checks only classic scripts; every file here is a module, so
      //   it could never report anything (undeclared assignments are no-undef's, above).
      // - no-use-before-define: flags module constants used inside methods that only run
      //   after the module has loaded (crane.js's HOME), which is fine.
      // - no-await-in-loop: the one loop with await pages through the jobs one request after
      //   another on purpose.
      // - no-shadow with builtinGlobals: dozens of locals named name, status, event, model.
    },
  },
];
