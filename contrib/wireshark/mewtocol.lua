-- Panasonic MEWTOCOL-COM, the computer link of FP-series PLCs, as rackd speaks it
-- (src/protocols/mewtocol, /work/shared/spec/mewtocol.md).
--
-- Frames: `%` (or `<`, long frame) + station (2 digits, or EE: global) + `#` command,
-- `$` response or `!` error + body + BCC (2 hex digits, or `**`) + CR. The BCC, the XOR of
-- every character before it, is checked (mewtocol.bcc_ok). Commands RCS, RCP, RCC, WCS, WCP,
-- WCC, RD, WD are taken apart; a response's data is read with its request (the last command
-- on the same link), so words show under their register numbers.
--
-- Serial captures name this dissector ("mewtocol") in their exported-PDU header. Over TCP
-- (a serial-to-Ethernet gateway) it is a heuristic on every port, and a Decode As choice
-- (`-d tcp.port==9094,mewtocol`); a port preference adds one port for good.

local mewtocol = Proto("mewtocol", "Panasonic MEWTOCOL-COM")

local commands = {
    RCS = "read one contact", RCP = "read contacts", RCC = "read contact words",
    WCS = "write one contact", WCP = "write contacts", WCC = "write contact words",
    RD = "read data area", WD = "write data area", RS = "read timer/counter set value",
    WS = "write timer/counter set value", RK = "read timer/counter elapsed value",
    WK = "write timer/counter elapsed value", MC = "register contacts to monitor",
    MD = "register data to monitor", MG = "monitoring start", SC = "preset contact area",
    SD = "preset data area", RR = "read system register", WR = "write system register",
    RT = "read the PLC status", RP = "read program", WP = "write program",
    RM = "remote control", AB = "abort",
}

-- Error codes, as src/protocols/mewtocol/error_code.rs words them.
local errors = {
    [40] = "BCC error", [41] = "format error", [42] = "command not supported",
    [43] = "procedure error (multi-frame)", [60] = "parameter error", [61] = "data error",
    [62] = "registration error", [63] = "PLC mode error",
    [65] = "protect error (write-protected memory)",
}

local data_areas = { D = "DT (data registers)", L = "LD (link registers)", F = "FL (file registers)" }

mewtocol.prefs.port = Pref.uint("TCP port", 0, "A TCP port to decode as MEWTOCOL-COM (0: none)")
mewtocol.prefs.heuristic = Pref.bool("Find MEWTOCOL frames on any TCP port", true,
    "Try TCP payloads that look like a whole MEWTOCOL-COM frame")

local f = {
    start = ProtoField.string("mewtocol.start", "Start"),
    long = ProtoField.bool("mewtocol.long", "Long frame"),
    station = ProtoField.string("mewtocol.station", "Station"),
    type = ProtoField.string("mewtocol.type", "Type"),
    command = ProtoField.string("mewtocol.command", "Command"),
    response_code = ProtoField.string("mewtocol.response_code", "Response code"),
    area = ProtoField.string("mewtocol.area", "Area"),
    first = ProtoField.uint32("mewtocol.first", "First", base.DEC),
    last = ProtoField.uint32("mewtocol.last", "Last", base.DEC),
    count = ProtoField.uint32("mewtocol.count", "Count", base.DEC),
    contact = ProtoField.string("mewtocol.contact", "Contact"),
    contact_value = ProtoField.uint8("mewtocol.contact_value", "Contact state", base.DEC),
    word = ProtoField.uint16("mewtocol.word", "Word", base.DEC),
    register = ProtoField.string("mewtocol.register", "Register"),
    error_code = ProtoField.uint8("mewtocol.error_code", "Error code", base.DEC, errors),
    error = ProtoField.string("mewtocol.error", "Error"),
    bcc = ProtoField.string("mewtocol.bcc", "BCC"),
    bcc_computed = ProtoField.uint8("mewtocol.bcc_computed", "BCC computed", base.HEX),
    bcc_ok = ProtoField.bool("mewtocol.bcc_ok", "BCC good"),
    body = ProtoField.string("mewtocol.body", "Body"),
    request_in = ProtoField.framenum("mewtocol.request_in", "Request in frame", base.NONE),
}
mewtocol.fields = f

local e = {
    bad_bcc = ProtoExpert.new("mewtocol.bcc.bad", "BCC does not match",
        expert.group.CHECKSUM, expert.severity.ERROR),
    error = ProtoExpert.new("mewtocol.error.reply", "The PLC answered with an error code",
        expert.group.RESPONSE_CODE, expert.severity.WARN),
    malformed = ProtoExpert.new("mewtocol.malformed", "Not a MEWTOCOL-COM frame",
        expert.group.MALFORMED, expert.severity.ERROR),
}
mewtocol.experts = { e.bad_bcc, e.error, e.malformed }

local pending, answers = {}, {}
function mewtocol.init()
    pending, answers = {}, {}
end

-- XOR of two bytes, in arithmetic (Lua 5.2's bit32 and 5.4's operators differ; this runs
-- on both).
local function xor8(a, b)
    local r, v = 0, 1
    for _ = 1, 8 do
        if (a % 2) ~= (b % 2) then r = r + v end
        a, b, v = math.floor(a / 2), math.floor(b / 2), v * 2
    end
    return r
end

local function xor(tvb, offset, len)
    local bcc = 0
    for i = offset, offset + len - 1 do
        bcc = xor8(bcc, tvb(i, 1):uint())
    end
    return bcc
end

-- 4 hex characters, low byte first ("2A00" is 42).
local function word_at(text, i)
    local lo = tonumber(text:sub(i, i + 1), 16)
    local hi = tonumber(text:sub(i + 2, i + 3), 16)
    if not lo or not hi then return nil end
    return hi * 256 + lo
end

-- Words from `at` (tvb offset) for `n` words; labels from area/first when known.
local function add_words(tree, tvb, at, stop, label, first)
    local text = tvb(at, stop - at):string()
    local i, n = 1, 0
    while i + 3 <= #text do
        local w = word_at(text, i)
        if not w then break end
        local item = tree:add(f.word, tvb(at + i - 1, 4), w)
        if label then
            local name = label .. (first + n)
            item:set_text(string.format("%s: %d (0x%04X)", name, w, w))
            item:add(f.register, name):set_generated()
        end
        i, n = i + 4, n + 1
    end
    return n
end

local function add_contact(tree, tvb, at)
    local text = tvb(at, 5):string()
    tree:add(f.contact, tvb(at, 5), text)
    return text
end

local function digits(tvb, at, n)
    return tonumber(tvb(at, n):string())
end

-- The command body; returns what a response needs and an Info text.
local function dissect_command(tvb, tree, at, stop)
    local len = stop - at
    if len < 2 then return nil, "command" end
    local two = tvb(at, 2):string()
    local code = two
    if (two == "RC" or two == "WC") and len >= 3 then code = tvb(at, 3):string() end
    tree:add(f.command, tvb(at, #code), code):append_text(" (" .. (commands[code] or "unknown command") .. ")")
    local req = { code = code }
    local p = at + #code
    if code == "RD" or code == "WD" then
        if stop - p < 11 then return req, code end
        local area = tvb(p, 1):string()
        tree:add(f.area, tvb(p, 1), area):append_text(" (" .. (data_areas[area] or "?") .. ")")
        local first, last = digits(tvb, p + 1, 5), digits(tvb, p + 6, 5)
        if not first or not last then return req, code end
        tree:add(f.first, tvb(p + 1, 5), first)
        tree:add(f.last, tvb(p + 6, 5), last)
        tree:add(f.count, tvb(p + 1, 10), last - first + 1):set_generated()
        local label = area == "D" and "DT" or (area == "L" and "LD" or "FL")
        req.label, req.first = label, first
        if code == "WD" then add_words(tree, tvb, p + 11, stop, label, first) end
        return req, string.format("%s %s%d..%s%d", code, label, first, label, last)
    elseif code == "RCC" or code == "WCC" then
        if stop - p < 9 then return req, code end
        local area = tvb(p, 1):string()
        tree:add(f.area, tvb(p, 1), area)
        local first, last = digits(tvb, p + 1, 4), digits(tvb, p + 5, 4)
        if not first or not last then return req, code end
        tree:add(f.first, tvb(p + 1, 4), first)
        tree:add(f.last, tvb(p + 5, 4), last)
        tree:add(f.count, tvb(p + 1, 8), last - first + 1):set_generated()
        req.label, req.first = "W" .. area, first
        if code == "WCC" then add_words(tree, tvb, p + 9, stop, "W" .. area, first) end
        return req, string.format("%s W%s%d..W%s%d", code, area, first, area, last)
    elseif code == "RCS" or code == "WCS" then
        if stop - p < 5 then return req, code end
        local c = add_contact(tree, tvb, p)
        if code == "WCS" and stop - p >= 6 then
            tree:add(f.contact_value, tvb(p + 5, 1), digits(tvb, p + 5, 1) or 0)
            return req, string.format("%s %s := %s", code, c, tvb(p + 5, 1):string())
        end
        return req, code .. " " .. c
    elseif code == "RCP" or code == "WCP" then
        local n = digits(tvb, p, 1) or 0
        tree:add(f.count, tvb(p, 1), n)
        local item = code == "RCP" and 5 or 6
        local at2 = p + 1
        for _ = 1, n do
            if at2 + item > stop then break end
            add_contact(tree, tvb, at2)
            if code == "WCP" then tree:add(f.contact_value, tvb(at2 + 5, 1), digits(tvb, at2 + 5, 1) or 0) end
            at2 = at2 + item
        end
        return req, string.format("%s %d contacts", code, n)
    end
    return req, code
end

local function dissect_response(tvb, tree, at, stop, req)
    if stop - at < 2 then return "response" end
    local code = tvb(at, 2):string()
    tree:add(f.response_code, tvb(at, 2), code)
    local p = at + 2
    if code == "RD" or (code == "RC" and req and req.code == "RCC") then
        local n = add_words(tree, tvb, p, stop, req and req.label, req and req.first or 0)
        return string.format("%s %d words", code, n)
    elseif code == "RC" then
        for i = p, stop - 1 do
            tree:add(f.contact_value, tvb(i, 1), digits(tvb, i, 1) or 0)
        end
        return code .. " " .. (stop > p and tvb(p, stop - p):string() or "")
    end
    return code
end

-- One whole frame in tvb (start character to CR); returns nothing.
local function dissect_frame(tvb, pinfo, root)
    local len = tvb:len()
    local tree = root:add(mewtocol, tvb())
    if len < 7 then
        tree:add_proto_expert_info(e.malformed)
        return
    end
    local start = tvb(0, 1):string()
    tree:add(f.start, tvb(0, 1), start)
    tree:add(f.long, tvb(0, 1), start == "<"):set_generated()
    local station = tvb(1, 2):string()
    tree:add(f.station, tvb(1, 2), station):append_text(station == "EE" and " (global)" or "")
    local mark = tvb(3, 1):string()
    local types = { ["#"] = "command", ["$"] = "response", ["!"] = "error" }
    tree:add(f.type, tvb(3, 1), types[mark] or mark)
    local bcc_at = len - 3
    local key = tostring(pinfo.src) .. pinfo.src_port .. ">" .. tostring(pinfo.dst) .. pinfo.dst_port
    local back = tostring(pinfo.dst) .. pinfo.dst_port .. ">" .. tostring(pinfo.src) .. pinfo.src_port
    local info
    if mark == "#" then
        tree:add(f.body, tvb(4, bcc_at - 4))
        local req
        req, info = dissect_command(tvb, tree, 4, bcc_at)
        if req and not pinfo.visited then
            req.frame = pinfo.number
            pending[key] = req
        end
        info = "Command " .. info
    elseif mark == "$" then
        tree:add(f.body, tvb(4, bcc_at - 4))
        if not pinfo.visited then
            answers[pinfo.number] = pending[back]
            pending[back] = nil
        end
        local req = answers[pinfo.number]
        if req then tree:add(f.request_in, req.frame):set_generated() end
        info = "Response " .. dissect_response(tvb, tree, 4, bcc_at, req)
    elseif mark == "!" then
        if not pinfo.visited then
            answers[pinfo.number] = pending[back]
            pending[back] = nil
        end
        local code = tonumber(tvb(4, 2):string()) or 0
        local item = tree:add(f.error_code, tvb(4, 2), code)
        item:add(f.error, tvb(4, 2), errors[code] or "unknown MEWTOCOL error code"):set_generated()
        item:add_proto_expert_info(e.error)
        info = string.format("Error %02d: %s", code, errors[code] or "unknown MEWTOCOL error code")
    else
        tree:add_proto_expert_info(e.malformed)
        info = "?"
    end
    local bcc_text = tvb(bcc_at, 2):string()
    local bcc_item = tree:add(f.bcc, tvb(bcc_at, 2), bcc_text)
    if bcc_text == "**" then
        bcc_item:append_text(" (not checked: the sender skipped it)")
    else
        local computed = xor(tvb, 0, bcc_at)
        local received = tonumber(bcc_text, 16)
        bcc_item:add(f.bcc_computed, tvb(bcc_at, 2), computed):set_generated()
        bcc_item:add(f.bcc_ok, tvb(bcc_at, 2), computed == received):set_generated()
        if computed ~= received then
            bcc_item:add_proto_expert_info(e.bad_bcc)
            info = info .. " [BCC error]"
        end
    end
    pinfo.cols.info:append(string.format("%s%s %s  ", start, station, info))
    if pinfo.port_type == 0 then
        -- A serial line has no addresses: name the ends by the frame's own direction.
        local plc = "station " .. station
        pinfo.cols.src = mark == "#" and "computer" or plc
        pinfo.cols.dst = mark == "#" and plc or "computer"
    end
end

local function plausible(tvb)
    if tvb:len() < 7 then return false end
    local s = tvb(0, 1):uint()
    if s ~= 0x25 and s ~= 0x3C then return false end
    local st = tvb(1, 2):string()
    if not (st:match("^%d%d$") or st == "EE") then return false end
    local m = tvb(3, 1):string()
    return m == "#" or m == "$" or m == "!"
end

function mewtocol.dissector(tvb, pinfo, root)
    pinfo.cols.protocol = "MEWTOCOL"
    pinfo.cols.info:clear()
    local len = tvb:len()
    local offset = 0
    local tcp = pinfo.port_type == 2
    while offset < len do
        local cr = nil
        for i = offset, len - 1 do
            if tvb(i, 1):uint() == 0x0D then cr = i break end
        end
        if not cr then
            if tcp then
                pinfo.desegment_offset = offset
                pinfo.desegment_len = DESEGMENT_ONE_MORE_SEGMENT
                return len
            end
            dissect_frame(tvb(offset):tvb(), pinfo, root)
            return len
        end
        dissect_frame(tvb(offset, cr - offset + 1):tvb(), pinfo, root)
        offset = cr + 1
    end
    return len
end

local function heuristic(tvb, pinfo, root)
    if not mewtocol.prefs.heuristic or not plausible(tvb) then return false end
    if tvb(tvb:len() - 1, 1):uint() ~= 0x0D then return false end
    pinfo.conversation = mewtocol
    mewtocol.dissector(tvb, pinfo, root)
    return true
end

local registered_port = 0
function mewtocol.prefs_changed()
    local tcp = DissectorTable.get("tcp.port")
    if registered_port ~= 0 then tcp:remove(registered_port, mewtocol) end
    registered_port = mewtocol.prefs.port
    if registered_port ~= 0 then tcp:add(registered_port, mewtocol) end
end

DissectorTable.get("tcp.port"):add_for_decode_as(mewtocol)
mewtocol:register_heuristic("tcp", heuristic)
