// browser_shot.mjs — a real browser on the daemon's page: headless Chromium driven over the
// DevTools protocol (--remote-debugging-pipe: JSON messages on fds 3 and 4, NUL-separated),
// no npm package needed. Opens URL, waits until the page's title says the globe's tiles are
// loaded (or an error, or the time limit), waits for one more second of frames, saves a
// screenshot, and prints the console errors and exceptions it saw.
// usage: node browser_shot.mjs URL OUT.png [SECONDS]
// exit: 0 loaded, 1 an error in the page, 2 timed out, 3 the browser failed.
import { spawn } from "node:child_process";
import { writeFileSync, mkdtempSync, rmSync } from "node:fs";
import { tmpdir } from "node:os";
import { join } from "node:path";

const [url, out, secs = "120"] = process.argv.slice(2);
const profile = mkdtempSync(join(tmpdir(), "clipmap-chromium-"));
const chrome = spawn("chromium", [
	"--headless=new", "--no-sandbox", "--disable-gpu-sandbox", "--use-angle=swiftshader",
	"--enable-unsafe-swiftshader", "--window-size=800,600", "--no-first-run",
	"--disable-extensions", "--disable-background-networking", `--user-data-dir=${profile}`,
	"--remote-debugging-pipe", "about:blank",
], { stdio: ["ignore", "ignore", "ignore", "pipe", "pipe"] });
const toChrome = chrome.stdio[3], fromChrome = chrome.stdio[4];
let id = 0, buf = "";
const waiting = new Map(), errors = [];
function send(method, params = {}, sessionId) {
	const msg = { id: ++id, method, params };
	if (sessionId) msg.sessionId = sessionId;
	toChrome.write(JSON.stringify(msg) + "\0");
	return new Promise((ok, fail) => waiting.set(msg.id, { ok, fail }));
}
fromChrome.on("data", d => {
	buf += d.toString();
	let z;
	while ((z = buf.indexOf("\0")) >= 0) {
		const m = JSON.parse(buf.slice(0, z));
		buf = buf.slice(z + 1);
		if (m.id && waiting.has(m.id)) {
			const w = waiting.get(m.id);
			waiting.delete(m.id);
			m.error ? w.fail(new Error(m.error.message)) : w.ok(m.result);
		} else if (m.method === "Runtime.consoleAPICalled" && m.params.type === "error") {
			errors.push("console.error: " + m.params.args.map(a => a.value ?? a.description).join(" "));
		} else if (m.method === "Runtime.exceptionThrown") {
			const e = m.params.exceptionDetails;
			errors.push("exception: " + (e.exception?.description ?? e.text));
		}
	}
});
const finish = code => {
	for (const e of errors) console.log(e);
	chrome.kill("SIGKILL");
	chrome.on("exit", () => {
		try { rmSync(profile, { recursive: true, force: true }); } catch { /* left in /tmp */ }
		process.exit(code);
	});
};
chrome.on("error", e => { console.log("chromium: " + e.message); finish(3); });
setTimeout(() => { console.log("timed out"); finish(2); }, (Number(secs) + 30) * 1000).unref();
try {
	const { targetId } = await send("Target.createTarget", { url: "about:blank" });
	const { sessionId } = await send("Target.attachToTarget", { targetId, flatten: true });
	await send("Runtime.enable", {}, sessionId);
	await send("Page.enable", {}, sessionId);
	await send("Page.navigate", { url }, sessionId);
	const end = Date.now() + Number(secs) * 1000;
	let title = "";
	while (Date.now() < end) {
		const r = await send("Runtime.evaluate", { expression: "document.title" }, sessionId);
		title = r.result.value;
		if (title === "clipmapd: loaded" || title === "clipmapd: error") break;
		await new Promise(ok => setTimeout(ok, 500));
	}
	await new Promise(ok => setTimeout(ok, 1000));
	const shot = await send("Page.captureScreenshot", { format: "png" }, sessionId);
	writeFileSync(out, Buffer.from(shot.data, "base64"));
	console.log("title: " + title);
	finish(title === "clipmapd: loaded" && !errors.length ? 0 : title === "clipmapd: error" || errors.length ? 1 : 2);
} catch (e) {
	console.log("devtools: " + e.message);
	finish(3);
}
